"""Many candidate poses scored against one frame at once: the coarse stage of the first
pose's search (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`) and of a lost limb's
(:mod:`~meshmocap.estimate.recovery.reinit`).

A candidate is a whole pose (local rotations and root position). It is scored by the same
symmetric clipped distance as :meth:`~meshmocap.estimate.pose.fit.PoseFitter.score`, made cheap
enough to score tens of thousands of candidates in a few seconds:

* the template is reduced to a few hundred surface points, each carried rigidly by the
  joint that weighs most on it (:func:`body_sample`), so posing a candidate costs one small
  product per point instead of linear-blend skinning;
* model → data: how far each of those points stands outside the observed solid, read from a
  coarse signed distance of the occupancy (:class:`FrameScorer`, nearest grid point);
* data → model: each of a few hundred observed surface points (farthest-point sampled, so
  hands and feet are in) to its nearest model point.

Both clipped as :data:`~meshmocap.estimate.pose.fit.SCORE_CLIP` and
:data:`~meshmocap.estimate.pose.fit.OUTSIDE_CLIP`. Metres, world frame Z up.

References
----------
- T. F. Gonzalez, *Clustering to minimize the maximum intercluster distance*,
  Theoretical Computer Science 38:293–306, 1985.
  https://doi.org/10.1016/0304-3975(85)90224-5
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.estimate.pose.fit import OUTSIDE_CLIP, SCORE_CLIP
from meshmocap.geometry.camera import Camera, project
from meshmocap.geometry.distance_field import signed_distance
from meshmocap.geometry.rotations import so3_exp

__all__ = [
    "BodySample",
    "FrameScorer",
    "body_sample",
    "farthest_point_indices",
    "headings_removed",
    "sample_positions",
    "turned_about_z",
]


def farthest_point_indices(X: np.ndarray, n: int, *, first: int = 0) -> np.ndarray:
    """(min(n, len(X)),) int64: indices of ``X`` (k, 3) picked by farthest-point sampling
    from row ``first`` (each the point farthest from those already picked)."""
    X = np.asarray(X, dtype=np.float64)
    n = min(int(n), len(X))
    pick = np.empty(n, dtype=np.int64)
    pick[0] = first
    diff = X - X[first]
    d = np.einsum("ij,ij->i", diff, diff)  # squared: the same order, half the time
    for k in range(1, n):
        pick[k] = int(np.argmax(d))
        np.subtract(X, X[pick[k]], out=diff)
        np.minimum(d, np.einsum("ij,ij->i", diff, diff), out=d)
    return pick


@dataclass(frozen=True, eq=False)
class BodySample:
    """Template surface points carried rigidly by one joint each.

    Attributes
    ----------
    vertex : (m,) int64, the template vertices sampled
    joint : (m,) int64, the rig joint carrying each (its largest skinning weight)
    offset : (m, 3) float64, the rest vertex relative to its joint's rest position, metres
    """

    vertex: np.ndarray
    joint: np.ndarray
    offset: np.ndarray


_SAMPLES: dict[tuple, BodySample] = {}


def body_sample(template: Template, n: int = 200) -> BodySample:
    """``n`` of the template's rest vertices spread over its surface (farthest-point
    sampling from the lowest vertex), each carried by its dominant joint; cached per
    template."""
    key = (
        template.name,
        template.n_vertices,
        template.V[:: max(1, len(template.V) // 50)].tobytes(),
        n,
    )
    if key not in _SAMPLES:
        if len(_SAMPLES) > 16:
            _SAMPLES.clear()
        _SAMPLES[key] = _body_sample(template, n)
    return _SAMPLES[key]


def _body_sample(template: Template, n: int) -> BodySample:
    V = template.V
    vertex = farthest_point_indices(V, n, first=int(np.argmin(V[:, 2])))
    W = template.weights[vertex].toarray()
    joint = np.argmax(W, axis=1).astype(np.int64)
    offset = V[vertex] - template.skeleton.rest_positions[joint]
    return BodySample(vertex, joint, offset)


def sample_positions(sample: BodySample, G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(..., m, 3) float64: the sample's points for posed skeletons with global joint
    rotations ``G`` (..., J, 3, 3) and joint positions ``P`` (..., J, 3)
    (:func:`~meshmocap.body.skeleton.forward_kinematics`), metres."""
    return (
        np.einsum("...mab,mb->...ma", G[..., sample.joint, :, :], sample.offset)
        + P[..., sample.joint, :]
    )


def turned_about_z(R: np.ndarray, heading: np.ndarray | float) -> np.ndarray:
    """Local rotations ``R`` (..., J, 3, 3) with the root turned by ``heading`` radians
    about the vertical axis (a copy)."""
    h = np.asarray(heading, dtype=np.float64)
    Rz = so3_exp(np.stack([np.zeros_like(h), np.zeros_like(h), h], axis=-1))
    out = np.array(R, dtype=np.float64)
    out[..., 0, :, :] = Rz @ out[..., 0, :, :]
    return out


def headings_removed(R: np.ndarray, front: np.ndarray) -> np.ndarray:
    """Poses ``R`` (N, J, 3, 3) turned about the vertical so that the root's ``front``
    (3,), a rest-frame horizontal direction, faces that same direction (heading 0): the
    pose's heading left to the search."""
    f = np.asarray(front, dtype=np.float64)
    g = R[:, 0] @ f
    yaw = np.arctan2(g[:, 1], g[:, 0]) - np.arctan2(f[1], f[0])
    return turned_about_z(R, -yaw)


class FrameScorer:
    """Scores of many posed samples against one frame's observations (module docstring).

    Parameters
    ----------
    occupancy : (nx, ny, nz) bool
        The observed solid (a visual hull's voxels), True inside.
    origin : (3,) float64
        Centre of voxel (0, 0, 0), metres.
    voxel_size : float
        Voxel edge, metres.
    points : (p, 3) float64
        Observed surface points, metres.
    n_points : int
        Observed points used (farthest-point sampled).
    cameras, masks : list of Camera and of (height, width) bool, optional
        The frame's cameras and silhouettes: the data → model term is then measured in the
        images instead (each of ``n_pixels`` silhouette pixels per camera, farthest-point
        sampled, to the nearest projected model point, in metres at the observed centre's
        depth), which a visual hull's phantom volume does not fool.
    stride : int
        The coarse signed distance keeps every ``stride``-th voxel along each axis (a
        coarse voxel is occupied where any of its voxels is).
    """

    def __init__(
        self,
        occupancy: np.ndarray,
        origin: np.ndarray,
        voxel_size: float,
        points: np.ndarray,
        *,
        n_points: int = 200,
        stride: int = 2,
        cameras: list[Camera] | None = None,
        masks: list[np.ndarray] | None = None,
        n_pixels: int = 60,
    ):
        occ = np.asarray(occupancy, dtype=bool)
        s = int(stride)
        pad = [(0, -n % s) for n in occ.shape]
        occ = np.pad(occ, pad)
        nx, ny, nz = (n // s for n in occ.shape)
        occ = occ.reshape(nx, s, ny, s, nz, s).any(axis=(1, 3, 5))
        occ = np.pad(occ, 1)
        self.h = float(voxel_size) * s
        # centre of coarse voxel 0: the mean of the fine voxel centres it gathers, one out
        self.origin = np.asarray(origin, dtype=np.float64) + 0.5 * (s - 1) * voxel_size - self.h
        self.sdf = signed_distance(occ, self.h).astype(np.float32)
        self.shape = np.array(self.sdf.shape)
        P = np.asarray(points, dtype=np.float64)
        first = int(np.argmin(P[:, 2])) if len(P) else 0
        self.Y = P[farthest_point_indices(P, n_points, first=first)].astype(np.float32)
        self.centre = P.mean(axis=0) if len(P) else np.zeros(3)
        #: per camera with a silhouette: (camera, metres per pixel, sampled pixels (k, 2)
        #: in metres)
        self.views: list[tuple[Camera, float, np.ndarray]] = []
        for cam, mask in zip(cameras or [], masks or [], strict=False):
            rows, cols = np.nonzero(mask)
            _, depth = project(self.centre, cam.K, cam.R, cam.t)
            if not len(rows) or depth <= 0:
                continue
            uv = np.stack([cols, rows], axis=1).astype(np.float64)
            scale = float(depth) / float(cam.K[0, 0])
            pick = farthest_point_indices(uv, n_pixels, first=int(np.argmin(rows)))
            self.views.append((cam, scale, (uv[pick] * scale).astype(np.float32)))

    def outside(self, X: np.ndarray) -> np.ndarray:
        """(...) float64: signed distance of the points ``X`` (..., 3) to the observed
        solid (metres, negative inside), at the nearest coarse grid point; beyond the grid
        its border value plus the distance to the grid."""
        g = (np.asarray(X) - self.origin) / self.h
        i = np.clip(np.rint(g), 0, self.shape - 1)
        beyond = np.linalg.norm(g - i, axis=-1) * self.h
        i = i.astype(np.int64)
        return self.sdf[i[..., 0], i[..., 1], i[..., 2]] + np.where(
            (g < 0).any(-1) | (g > self.shape - 1).any(-1), beyond, 0.0
        )

    def _nearest(
        self, x: np.ndarray, Y: np.ndarray, *, index: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """For candidates' points ``x`` (c, m, 3) float32 and observed points ``Y``
        (k, 3): each observed point's squared distance to its nearest model point (c, k)
        float32 and, with ``index``, that point's index (c, k) int64, else None (compiled
        loops, :mod:`meshmocap.estimate.pose._kernels`)."""
        from meshmocap.estimate.pose._kernels import nearest_d2_kernel, nearest_kernel

        x = np.ascontiguousarray(x, dtype=np.float32)
        Yt = np.ascontiguousarray(np.asarray(Y, dtype=np.float32).T)
        return nearest_kernel(x, Yt) if index else (nearest_d2_kernel(x, Yt), None)

    def _data_d2(self, x: np.ndarray, n_data: int | None) -> np.ndarray:
        """(c, k) float32: each observed point's (or, with cameras, sampled silhouette
        pixel's) squared distance to the nearest of the candidates' points ``x``
        (c, m, 3) float32, the first ``n_data`` of each."""
        if not self.views:
            return self._nearest(x, self.Y[:n_data], index=False)[0]
        return np.concatenate(
            [
                self._nearest(
                    (project(x, cam.K, cam.R, cam.t)[0] * scale).astype(np.float32),
                    pix[:n_data],
                    index=False,
                )[0]
                for cam, scale, pix in self.views
            ],
            axis=1,
        )

    def score(
        self, X: np.ndarray, *, n_model: int | None = None, n_data: int | None = None
    ) -> np.ndarray:
        """(C,) float64: the symmetric clipped RMS distance (metres) of each candidate's
        points ``X`` (C, m, 3) to the observations (module docstring); with ``n_model``
        and ``n_data``, on the first that many model and observed points only (both are
        farthest-point ordered, so any prefix spreads over the body: a cheaper, coarser
        score)."""
        X = np.asarray(X)[:, :n_model]
        Y = self.Y[:n_data]
        out = np.empty(len(X))
        chunk = max(1, 2_000_000 // (X.shape[1] * len(Y)))
        for a in range(0, len(X), chunk):
            x = X[a : a + chunk].astype(np.float32)
            d1 = np.clip(self.outside(x), 0.0, OUTSIDE_CLIP)
            d2 = np.minimum(np.sqrt(self._data_d2(x, n_data)), SCORE_CLIP)
            out[a : a + chunk] = np.sqrt(0.5 * ((d1**2).mean(axis=1) + (d2**2).mean(axis=1)))
        return out

    def score_shared(
        self, X: np.ndarray, still: np.ndarray, *, n_data: int | None = None
    ) -> np.ndarray:
        """(C,) float64: :meth:`score` of candidates whose points are ``still`` (s, 3),
        the same for every candidate (e.g. the body but one limb), and their own ``X``
        (C, m, 3); the still points' terms computed once. Equal to :meth:`score` of
        the points joined, up to the order of the sums (rounding)."""
        X = np.asarray(X)
        S = np.asarray(still, dtype=np.float32)[None]
        n = X.shape[1] + S.shape[1]
        s1 = float((np.clip(self.outside(S[0]), 0.0, OUTSIDE_CLIP) ** 2).sum())
        s2 = self._data_d2(S, n_data)  # (1, k)
        out = np.empty(len(X))
        chunk = max(1, 2_000_000 // (max(X.shape[1], 1) * s2.shape[1]))
        for a in range(0, len(X), chunk):
            x = X[a : a + chunk].astype(np.float32)
            d1 = np.clip(self.outside(x), 0.0, OUTSIDE_CLIP)
            d2 = np.minimum(np.sqrt(np.minimum(self._data_d2(x, n_data), s2)), SCORE_CLIP)
            out[a : a + chunk] = np.sqrt(
                0.5 * ((s1 + (d1**2).sum(axis=1)) / n + (d2**2).mean(axis=1))
            )
        return out

    def shift(self, X: np.ndarray) -> np.ndarray:
        """(C, 3) float64: one ICP step of translation for each candidate's points ``X``
        (C, m, 3): the mean offset from each observed point's nearest model point to it,
        over the pairs closer than :data:`~meshmocap.estimate.pose.fit.SCORE_CLIP`."""
        X = np.asarray(X)
        out = np.zeros((len(X), 3))
        Y = self.Y
        chunk = max(1, 2_000_000 // (X.shape[1] * len(Y)))
        for a in range(0, len(X), chunk):
            x = X[a : a + chunk].astype(np.float32)
            d2, k = self._nearest(x, Y)
            near = np.take_along_axis(x, k[..., None], axis=1)  # (c, M, 3)
            ok = d2 < SCORE_CLIP**2
            n = np.maximum(ok.sum(axis=1), 1)[:, None]
            out[a : a + chunk] = ((Y[None] - near) * ok[..., None]).sum(axis=1) / n
        return out


def posed_samples(
    template: Template, sample: BodySample, R: np.ndarray, root: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The sample points (C, m, 3) and joint positions (C, J, 3) of poses ``R``
    (C, J, 3, 3) at root positions ``root`` (C, 3), metres."""
    G, P = forward_kinematics(template.skeleton, R, root)
    return sample_positions(sample, G, P), P
