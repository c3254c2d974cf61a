"""Residuals and Gauss–Newton rows of the patch tracker's terms beyond the paper's Eq. (1)
(issue 20; the terms themselves: :mod:`~meshmocap.trackers.patch.terms`): a silhouette
coverage term that uses the capture's cameras and silhouettes, not only the hull, and a
temporal prior on the joints. (The rows of Eq. (1)'s terms are assembled by
:mod:`~meshmocap.trackers.patch.solver`.)

* **Silhouette coverage** (``lambda_silhouette``). The hull's points cannot tell a limb on
  the true surface from one in a phantom wedge beside it: both lie on the hull and both
  project inside every silhouette. But the true surface covers every silhouette pixel, and
  a limb in a phantom wedge leaves the true limb's pixels uncovered in some view
  (:mod:`meshmocap.geometry.coverage`). For each such pixel, the nearest projected model
  vertex is pulled onto the pixel's viewing ray (point-to-ray distance, the closest point
  of the ray held fixed for the Gauss–Newton step as ICP holds its correspondences), with
  Cauchy weights ``1 / (1 + (gap/τ)²)`` so that spurious silhouette blobs far from the body
  pull little.
* **Temporal prior** (``lambda_temporal``). Each joint is held softly at its
  constant-velocity prediction ``x̂_t = x_(t−1) + (x_(t−1) − x_(t−2))`` (the frame's warm
  start, clipped): ``Σ_j |x_j − x̂_j|²``, an acceleration penalty. Where the data vanish or
  lie (a silhouette hole carving a limb away, a phantom blob), the limb coasts on its
  velocity instead of following the nearest wrong points; where there are data, they
  outweigh it.

Each term is normalised as the others (a mean squared residual, metres²) and added to a
:class:`~meshmocap.trackers.patch.solver.System`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap.geometry.camera import Camera
from meshmocap.geometry.coverage import mask_samples, pixel_rays, uncovered
from meshmocap.trackers.patch.solver import System, add_point_terms

#: Silhouette pixels sampled per camera and frame (on a regular grid).
SILHOUETTE_SAMPLES = 1500
#: Pixels farther than this (metres at the model's depth) from the model are not pulled
#: (a blob, or a limb the model lost: the data term's business).
SILHOUETTE_CAP = 0.3


@dataclass(frozen=True, eq=False)
class SilhouetteRays:
    """A frame's silhouette samples and their viewing rays, per camera.

    Attributes
    ----------
    cameras : list of Camera
    uv : list of (m_c, 2) float64 pixels of each camera's silhouette
    origin : list of (3,) camera centres; dirs : list of (m_c, 3) unit ray directions
    n : int, total number of samples
    """

    cameras: list
    uv: list
    origin: list
    dirs: list
    n: int


def silhouette_rays(cameras: list[Camera], masks: list[np.ndarray]) -> SilhouetteRays:
    """Sample each silhouette ``masks[c]`` (H, W) bool of ``cameras[c]`` on a grid of about
    :data:`SILHOUETTE_SAMPLES` pixels and cast their rays (cameras without a mask, or with
    an empty one, are left out)."""
    cams, uvs, origins, dirs = [], [], [], []
    for cam, mask in zip(cameras, masks, strict=False):
        area = int(np.count_nonzero(mask))
        if area == 0:
            continue
        stride = max(1, round(float(np.sqrt(area / SILHOUETTE_SAMPLES))))
        uv = mask_samples(mask, stride)
        o, d = pixel_rays(cam, uv)
        cams.append(cam), uvs.append(uv), origins.append(o), dirs.append(d)
    return SilhouetteRays(cams, uvs, origins, dirs, sum(len(u) for u in uvs))


def add_silhouette(
    sys: System,
    rays: SilhouetteRays,
    Vs: np.ndarray,
    patch: np.ndarray,
    q: np.ndarray,
    *,
    radius: float,
    scale: float,
    weight: float,
) -> tuple[float, float]:
    """Add ``weight · Σ w |P⊥(v − o)|² / m`` over the uncovered silhouette samples (module
    docstring): ``m`` samples in all, ``v`` the nearest projected vertex of each.

    Parameters
    ----------
    Vs : (s, 3) model vertices (as their own patches predict them), metres
    patch : (s,) int, their patches; q : (s, 3) their offsets ``R_k (v0 − c0_k)``
    radius : float, metres a vertex covers (about the vertices' spacing)
    scale : float, Cauchy scale τ of the weights, metres

    Returns
    -------
    tuple of float, the weighted mean squared distance (metres²) and the share of samples
    uncovered
    """
    total, n_out = 0.0, 0
    rows_p, rows_q, rows_r, rows_w = [], [], [], []
    for cam, uv, o, d in zip(rays.cameras, rays.uv, rays.origin, rays.dirs, strict=True):
        pix, j, gap = uncovered(cam, uv, Vs, radius=radius)
        keep = gap < SILHOUETTE_CAP
        pix, j, gap = pix[keep], j[keep], gap[keep]
        n_out += len(pix)
        if len(pix) == 0:
            continue
        v = Vs[j] - o
        dd = d[pix]
        r = v - dd * np.sum(v * dd, axis=1, keepdims=True)  # P⊥ (v − o): v to the ray
        rows_p.append(patch[j]), rows_q.append(q[j]), rows_r.append(r)
        rows_w.append(1.0 / (1.0 + (gap / scale) ** 2))
    if not rows_p or rays.n == 0:
        return 0.0, 0.0
    p, qq, r, w = (np.concatenate(a) for a in (rows_p, rows_q, rows_r, rows_w))
    total = add_point_terms(sys, p, qq, r, w, weight / rays.n)
    return total / rays.n, n_out / rays.n


def add_joint_prior(sys: System, X: np.ndarray, X_hat: np.ndarray, weight: float) -> float:
    """Add ``weight · Σ_j |x_j − x̂_j|²`` (the temporal prior, module docstring) for joints
    ``X`` (K, 3) and their predictions ``X_hat`` (K, 3), metres; returns the sum."""
    K = len(X)
    r = X - X_hat
    base = 6 * sys.pattern.n_patches
    sys.JJ[np.arange(3 * K), np.arange(3 * K)] += weight
    sys.g[base:] += weight * r.ravel()
    return float(np.sum(r * r))
