"""The patch tracker's energy terms (patch-skeleton-tracking.txt §III): one small frozen
dataclass per term, all with one interface.

A term has a ``name`` and a ``weight``; :meth:`Term.add` adds its rows, times its
:attr:`Term.coefficient`, to one Gauss–Newton :class:`~meshmocap.trackers.patch.solver.System`
and returns its value (a mean squared residual, metres²). The energy is a list of them
(:mod:`~meshmocap.trackers.patch.energy`): a step adds every term of the list to one system,
and the total is the sum over the same list of coefficient × value.

The terms of Eq. (1): :class:`DataTerm` (Eq. 7), :class:`RigidityTerm` (Eq. 2),
:class:`BoneTerm` (Eq. 11). Beyond the paper: :class:`ReverseTerm`, :class:`LengthTerm`,
:class:`SilhouetteTerm`, :class:`TemporalTerm`. What they read: :class:`FrameData` (fixed
over a frame) and :class:`Iterate` (one iteration's linearisation point, with the E-step's
:class:`Correspondences`).

Each term is normalised by its own total weight (a mean squared residual, metres²), so the
weights compare mean squared residuals whatever the number of points, patches or vertices
(the paper's sums, Eq. 2, 7 and 11, depend on them).

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- C. Cagniart, E. Boyer, S. Ilic, *Free-form mesh tracking: a patch-based
  approach*, IEEE Conference on Computer Vision and Pattern Recognition (CVPR), 2010.
- C. Cagniart, E. Boyer, S. Ilic, *Probabilistic deformable surface tracking from
  multiple videos*, European Conference on Computer Vision (ECCV), 2010.
- M. Straka, S. Hauswiesner, M. Rüther, H. Bischof, *Simultaneous shape and pose
  adaption of articulated models using linear optimization*, European Conference on
  Computer Vision (ECCV), 2012.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar, Protocol

import numpy as np

from meshmocap._tolerances import DIVISOR_FLOOR
from meshmocap.geometry.camera import Camera, in_view
from meshmocap.io.capture import CaptureFrame
from meshmocap.trackers.patch.kernels import add_moment_blocks, reverse_moments
from meshmocap.trackers.patch.model import PatchModel
from meshmocap.trackers.patch.nearest import NearestPoints
from meshmocap.trackers.patch.residuals import (
    SilhouetteRays,
    add_joint_prior,
    add_silhouette,
    silhouette_rays,
)
from meshmocap.trackers.patch.solver import (
    RigidityMoments,
    System,
    add_bone,
    add_bone_lengths,
    add_plane_vertex_terms,
    add_rigidity,
    add_vertex_terms,
    bone_joint_blocks,
)

#: Candidate observed points kept per reverse-term vertex across a frame's iterations
#: (:class:`~meshmocap.trackers.patch.nearest.NearestPoints`).
REVERSE_SPARE = 3
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
    def labels(self) -> np.ndarray:
        """(n,) int64, each vertex's patch."""
        return self.model.labels.astype(np.int64)

    @cached_property
    def bone_joints(self) -> np.ndarray:
        """The bone term's joint–joint blocks before its weight (3K, 3K), fixed over a
        frame (:func:`~meshmocap.trackers.patch.solver.bone_joint_blocks`)."""
        return bone_joint_blocks(self.model, len(self.X_hat))

    @cached_property
    def nearest_points(self) -> NearestPoints:
        """Nearest kept observed points of moving query points (the reverse term's
        vertices), built at first use, once a frame."""
        return NearestPoints(self.Y, spare=REVERSE_SPARE)

    def in_view(self, X: np.ndarray) -> np.ndarray:
        """(n,) bool: which of the points ``X`` (n, 3) every camera sees
        (:func:`~meshmocap.geometry.camera.in_view`)."""
        return in_view(X, self.cameras)

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
    """

    name: ClassVar[str]
    weight: float

    @property
    def coefficient(self) -> float:
        """The factor on :meth:`add`'s value in the total energy: ``weight``, times
        ``scale`` where the term has one (:class:`RigidityTerm`, :class:`BoneTerm`)."""
        ...

    def add(self, sys: System, it: Iterate) -> float:
        """Add ``coefficient · value`` to ``sys`` (its Gauss–Newton rows) and return the
        value at ``it`` (metres²)."""
        ...


class _Weighted:
    """Mixin: :attr:`Term.coefficient` from ``weight`` and ``scale`` (1 unless the term
    has a ``scale`` field)."""

    scale: float = 1.0
    weight: float

    @property
    def coefficient(self) -> float:
        return self.weight * self.scale


# Eq. (7): Edata(Θ) = Σ_i Σ_k w_i^k ‖y_i − x(v_i^k)‖²
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
        wd = max(float(w.sum()), DIVISOR_FLOOR)
        if self.residual == "point_to_plane":  # slide along the surface, with a little pull
            e = add_plane_vertex_terms(
                sys, patch, v, it.V, it.c, y, k.normal, w, self.coefficient / wd
            )
            add_vertex_terms(
                sys, patch, v, it.V, it.c, y, w, PLANE_POINT_MIX * self.coefficient / wd
            )
            return e / wd
        # Eq. (7) as printed
        return add_vertex_terms(sys, patch, v, it.V, it.c, y, w, self.coefficient / wd) / wd


# Eq. (2): Er(Θ) = Σ_k Σ_(l ∈ N_k) Σ_(v ∈ P_k ∪ P_l) w_kl ‖x_k(v) − x_l(v)‖²
@dataclass(frozen=True)
class RigidityTerm(_Weighted):
    """Er of Eq. (2), divided by the total rigidity weight ``Σ w_kl(v)``; ``scale``
    multiplies ``weight`` (``PatchOptions.rigidity_scale``: 1 in the paper's row)."""

    name: ClassVar[str] = "rigidity"
    weight: float = 1.0
    scale: float = 1.0

    def add(self, sys: System, it: Iterate) -> float:
        m = it.frame.model
        total = m.rig_w.sum()
        return add_rigidity(sys, m, it.frame.moments, it.R, it.c, self.coefficient / total) / total


# Eq. (11): Ebone(Θ, J) = Σ_k w_k ‖T_k(Δ0_k) − Δ_k‖²
@dataclass(frozen=True)
class BoneTerm(_Weighted):
    """Ebone of Eq. (11), divided by the total bone weight ``Σ w_k``; ``scale``
    multiplies ``weight`` (``PatchOptions.bone_scale``: 1 in the paper's row)."""

    name: ClassVar[str] = "bone"
    weight: float = 1.0
    scale: float = 1.0

    def add(self, sys: System, it: Iterate) -> float:
        m = it.frame.model
        total = m.bone_w.sum()
        joints = it.frame.bone_joints
        return add_bone(sys, m, it.R, it.c, it.X, self.coefficient / total, joints=joints) / total


# not in the paper: Σ_v ρ(d_v) ‖x(v) − y_nn(v)‖² / n (model to data)
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
        d, j = fd.nearest_points.query(it.V[v])
        ok = (np.einsum("ij,ij->i", it.N[v], fd.NY[j]) > fd.normal_cos) & (d < self.cap)
        near = np.flatnonzero(ok)
        ok[near] = fd.in_view(it.V[v[near]])
        n = int(np.count_nonzero(ok))
        if n == 0:
            return 0.0
        # Cauchy IRLS weights 1 / (1 + (d / scale)²), the moments in one pass
        W, s, Q, G, e = reverse_moments(
            ok, v, j, d, fd.labels, it.V, it.c, fd.Y, float(self.cauchy_scale), m.P
        )
        add_moment_blocks(sys.D, sys.g, W, s, Q, G, float(self.coefficient / n))
        return e / n


# not in the paper: Σ_(a,b) (‖x_a − x_b‖ − L_ab)² / n
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


# not in the paper: Σ_m ρ(gap_m) ‖P⊥(v_m − o_m)‖² / n over uncovered silhouette pixels
@dataclass(frozen=True)
class SilhouetteTerm(_Weighted):
    """Not in the paper: silhouette pixels that no model vertex covers pull their nearest
    projected vertex onto their viewing ray, Cauchy-weighted with ``cauchy_scale``
    (:func:`~meshmocap.trackers.patch.residuals.add_silhouette`); nothing where the frame has
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


# not in the paper: Σ_j ‖x_j − x̂_j‖² / K (x̂: constant-velocity prediction)
@dataclass(frozen=True)
class TemporalTerm(_Weighted):
    """Not in the paper: the mean squared distance of the joints from their
    constant-velocity prediction (an acceleration penalty,
    :func:`~meshmocap.trackers.patch.residuals.add_joint_prior`)."""

    name: ClassVar[str] = "temporal"
    weight: float = 1.0

    def add(self, sys: System, it: Iterate) -> float:
        K = len(it.X)
        return add_joint_prior(sys, it.X, it.frame.X_hat, self.coefficient / K) / K


def frame_masks(frame: CaptureFrame) -> list[np.ndarray]:
    """The frame's silhouettes, one per camera, or [] where the capture has none."""
    try:
        masks = frame.silhouettes
    except (OSError, AttributeError, ValueError):
        return []
    return masks if len(masks) == len(frame.cameras) else []
