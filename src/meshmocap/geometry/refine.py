"""A tracked surface refined towards one frame's observations, along its normals.

The skeleton-driven surface of a tracker (skinned patches, a cage) cannot follow what the
skeleton does not carry: clothing, muscles, a template rigged in another pose. Each frame,
:class:`SurfaceRefiner` moves every vertex ``i`` of that surface along its normal ``nᵢ`` by
a scalar ``uᵢ``, the minimiser of

    E(u) = Σᵢ wᵢ (uᵢ − dᵢ)²  +  α uᵀ L u  +  β Σᵢ uᵢ²

where ``dᵢ`` is the signed normal distance to the observed surface (a point-to-plane
residual, the patch paper's normal-compatible correspondences, §III-A: a vertex and its
observed point within ``reach`` whose normals agree within ``max_angle``; both ways,
vertex → nearest point and point → nearest vertex, averaged), ``wᵢ`` the number of such
correspondences (0 for a vertex with none: the hole of a hull, an occluded limb), ``L`` the
graph Laplacian of the mesh (a smooth displacement field keeps the template's detail, as
in Laplacian surface editing, Sorkine et al. 2004) and ``β`` a pull back to the tracked
surface, so a vertex without observation stays near where the skeleton put it (and no
vertex moves further than ``reach``). The normal
equations ``(W + αL + βI) u = W d`` are sparse, symmetric and positive definite, solved
by conjugate gradients. The refinement starts from the tracked surface every frame and
never feeds back into the tracker's state: it cannot drift.

Frames and units: any frame, metres.

References
----------
- O. Sorkine, D. Cohen-Or, Y. Lipman, M. Alexa, C. Rössl, H.-P. Seidel, *Laplacian
  surface editing*, Symposium on Geometry Processing (SGP), 2004.
  https://doi.org/10.1145/1057432.1057456
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from pykdtree.kdtree import KDTree
from scipy.sparse.linalg import cg

from meshmocap.errors import InputError
from meshmocap.geometry.mesh import edges_unique, vertex_normals

__all__ = ["SurfaceRefiner"]


class SurfaceRefiner:
    """The solver of a mesh's refinement towards observed points (module docstring).

    Parameters
    ----------
    F : (m, 3) int
        The tracked surface's triangles (its connectivity, fixed over the track).
    n_vertices : int
        Its number of vertices.
    reach : float
        Metres: a vertex and an observed point further apart are not matched.
    max_angle : float
        Degrees: a vertex and an observed point whose normals differ more are not matched.
    smoothness : float
        ``α``: weight of the Laplacian term (dimensionless; per correspondence).
    stiffness : float
        ``β``: pull of every vertex back to its tracked position.
    iterations : int
        Correspondences found again on the refined surface this many times (≥ 1).

    Attributes
    ----------
    laplacian_ : (n, n) sparse float64
        The mesh's graph Laplacian ``D − A``.
    """

    def __init__(
        self,
        F: np.ndarray,
        n_vertices: int,
        *,
        reach: float = 0.05,
        max_angle: float = 60.0,
        smoothness: float = 2.0,
        stiffness: float = 0.05,
        iterations: int = 2,
    ):
        F = np.asarray(F, dtype=np.int64)
        if F.ndim != 2 or F.shape[1] != 3 or (len(F) and (F.min() < 0 or F.max() >= n_vertices)):
            raise InputError(
                f"SurfaceRefiner: F must be (m, 3) indices below {n_vertices}, found {F.shape}"
            )
        for name, v in (("reach", reach), ("smoothness", smoothness), ("stiffness", stiffness)):
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"SurfaceRefiner: {name} must be > 0, found {v!r}")
        if not 0 < max_angle <= 180:
            raise InputError(f"SurfaceRefiner: max_angle must be in (0, 180], found {max_angle}")
        if int(iterations) < 1:
            raise InputError(f"SurfaceRefiner: iterations must be ≥ 1, found {iterations}")
        self.F, self.n = F, int(n_vertices)
        self.reach, self.cos = float(reach), float(np.cos(np.radians(max_angle)))
        self.alpha, self.beta, self.iterations = (
            float(smoothness),
            float(stiffness),
            int(iterations),
        )
        E, _ = edges_unique(F)
        A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(self.n, self.n))
        A = (A + A.T).tocsr()
        self.laplacian_ = (sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A).tocsr()

    def normal_targets(
        self, V: np.ndarray, N: np.ndarray, P: np.ndarray, NP: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per vertex, the weight ``wᵢ`` (number of matches, (n,)) and the mean signed
        normal distance ``dᵢ`` (n,) of its matches to the observed points ``P`` (p, 3) with
        normals ``NP`` (p, 3), metres; ``N`` (n, 3) the vertices' unit normals."""
        w, s = np.zeros(self.n), np.zeros(self.n)
        if not len(P):
            return w, s
        # vertex → nearest observed point
        dist, j = KDTree(P).query(V, k=1)
        j = j.astype(np.int64)
        ok = (dist < self.reach) & (np.einsum("ij,ij->i", N, NP[j]) > self.cos)
        d = np.einsum("ij,ij->i", P[j] - V, N)
        w += ok
        s += np.where(ok, d, 0.0)
        # observed point → nearest vertex (reaches what the surface misses: a flaring dress)
        dist, i = KDTree(V).query(P, k=1)
        i = i.astype(np.int64)
        ok = (dist < self.reach) & (np.einsum("ij,ij->i", N[i], NP) > self.cos)
        d = np.einsum("ij,ij->i", P - V[i], N[i])
        w += np.bincount(i[ok], minlength=self.n)
        s += np.bincount(i[ok], weights=d[ok], minlength=self.n)
        return w, np.divide(s, w, out=np.zeros(self.n), where=w > 0)

    def refine(self, V: np.ndarray, P: np.ndarray, NP: np.ndarray) -> np.ndarray:
        """The surface ``V`` (n, 3) moved along its normals towards the observed points
        ``P`` (p, 3) with outward unit normals ``NP`` (p, 3), metres; returns (n, 3)."""
        V0 = np.asarray(V, dtype=np.float64)
        P, NP = np.asarray(P, dtype=np.float64), np.asarray(NP, dtype=np.float64)
        N = vertex_normals(V0, self.F)
        u = np.zeros(self.n)
        for _ in range(self.iterations):
            Vk = V0 + u[:, None] * N
            w, d = self.normal_targets(Vk, N, P, NP)
            if not w.any():
                break
            # targets are measured from the current surface: as offsets from V0, u + d
            w = np.minimum(w, 4.0)  # a vertex many points chose counts as well matched
            A = sp.diags(w + self.beta) + self.alpha * self.laplacian_
            u, _ = cg(A, w * (u + d), x0=u, rtol=1e-6, maxiter=200)
            u = np.clip(u, -self.reach, self.reach)  # never further than reach from the skin
        return V0 + u[:, None] * N
