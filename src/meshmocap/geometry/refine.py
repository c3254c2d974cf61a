"""A tracked surface refined towards one frame's observations: along its normals, or as
rigidly as possible so that its vertices keep their place on the body.

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

A displacement along the normals cannot move a vertex that slid *along* the body (a skin
that cannot follow the real deformation, a joint a little off): on a real 4D capture that
tangential part is most of the per-vertex error. :class:`ArapRefiner` moves the vertices
freely instead, as rigidly as possible with respect to a rest shape (the template's, or
the frame before's refined surface: below; Sorkine & Alexa 2007): it minimises over the
vertices ``v`` and one rotation ``Rᵢ`` per vertex::

    E(v, R) = ½ Σᵢ Σ_{j∈N(i)} |(vᵢ − vⱼ) − Rᵢ (rᵢ − rⱼ)|²  +  λ Σᵢ |vᵢ − tᵢ|²  +  μ Σᵢ |vᵢ − sᵢ|²

(Eq. 3 of the paper with uniform weights, plus data terms) where ``r`` is the rest shape,
``s`` the tracked surface, and ``tᵢ`` the vertex projected onto the tangent plane of its
nearest compatible observed point (a point-to-plane target: nothing pulls a vertex along
the observed surface but the shape of its neighbourhood), or ``sᵢ`` where none is within
reach. Alternating the rotations (the local step: the rotation of each vertex's
neighbourhood, Eq. 6, from a rigid turn's rotation by a few iterations of Müller et al.
2016) and the vertices (the global step: ``(L + (λ + μ) I) v = b(R) + λ t + μ s``,
Eq. 9, whose matrix never changes: factorised once) lowers ``E``; each global step is
over-relaxed (``v ← v' + (ω − 1)(v' − v)``, ``1 ≤ ω < 2``), which the slow, smooth part of
the local–global iteration's error needs.

The rest shape carries the correspondence. Frame to frame (``anchor="previous"``, where
the frame before was the last one refined) the rest shape is that frame's refined surface:
a real body's surface 1/30 s later is nearly a rigid turn of each neighbourhood, while
against the template's rest it is not (muscles, clothes, a skin rigged in another pose):
anchored to the template, a refinement started from the true surface of a real capture
slides away from it along the body (``docs/guide/own_capture.rst`` has the measurements).
Each frame starts from the tracked surface, plus the refinement of the frame before it
turned with the skin (its share ``keep``: what is given back to the skin each frame bounds
the chain's drift). The result feeds back into the tracker only through the skeleton's
hold on 4D captures, which fits the frame before's refined surface
(:mod:`meshmocap.estimate.pose.hold`).

Frames and units: any frame, metres.

References
----------
- O. Sorkine, D. Cohen-Or, Y. Lipman, M. Alexa, C. Rössl, H.-P. Seidel, *Laplacian
  surface editing*, Symposium on Geometry Processing (SGP), 2004.
  https://doi.org/10.1145/1057432.1057456
- O. Sorkine, M. Alexa, *As-rigid-as-possible surface modeling*, Symposium on Geometry
  Processing (SGP), 2007.
- M. Müller, J. Bender, N. Chentanez, M. Macklin, *A robust method to extract the
  rotational part of deformations*, Motion in Games (MIG), 2016.
  https://doi.org/10.1145/2994258.2994269
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from pykdtree.kdtree import KDTree
from scipy.sparse.linalg import cg, splu

from meshmocap._tolerances import UNDERFLOW_FLOOR
from meshmocap._validate import check_choice
from meshmocap.errors import InputError
from meshmocap.geometry.mesh import edges_unique, vertex_normals
from meshmocap.geometry.rotations import cross, so3_exp

#: Added to ``|tr(Rᵀ A)|`` before the rotation step divides by it (a zero covariance).
_TRACE_FLOOR = 1e-9

__all__ = ["ArapRefiner", "SurfaceRefiner", "rotational_part"]


def _checked(owner: str, F: object, n: int, max_angle: float, iterations: int) -> np.ndarray:
    """``F`` as (m, 3) int64 indices below ``n``; the options both refiners share checked
    (errors name ``owner``)."""
    F = np.asarray(F, dtype=np.int64)
    if F.ndim != 2 or F.shape[1] != 3 or (len(F) and (F.min() < 0 or F.max() >= n)):
        raise InputError(f"{owner}: F must be (m, 3) indices below {n}, found {F.shape}")
    if not 0 < max_angle <= 180:
        raise InputError(f"{owner}: max_angle must be in (0, 180], found {max_angle}")
    if int(iterations) < 1:
        raise InputError(f"{owner}: iterations must be ≥ 1, found {iterations}")
    return F


def _graph_laplacian(F: np.ndarray, n: int) -> tuple[np.ndarray, sp.csr_matrix]:
    """The unique edges (m, 2) of triangles ``F`` and the graph Laplacian ``D − A`` (n, n)."""
    E, _ = edges_unique(F)
    A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    A = (A + A.T).tocsr()
    return E, (sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A).tocsr()


def _incidence(edges: np.ndarray, n: int) -> sp.csr_matrix:
    """(n, e) sparse: 1 where a vertex is an end of an edge (``edges`` (e, 2))."""
    e = np.arange(len(edges))
    return sp.csr_matrix(
        (np.ones(2 * len(edges)), (edges.T.ravel(), np.concatenate([e, e]))), shape=(n, len(e))
    )


def _rest_frames(
    rest: np.ndarray, edges: np.ndarray, incidence: sp.csr_matrix
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rest shape ``rest`` (n, 3) as the local step reads it: its edge vectors
    ``rᵢ − rⱼ`` (e, 3) over ``edges`` (e, 2) (``incidence``: :func:`_incidence`), each
    vertex neighbourhood's principal axes (n, 3, 3: widest first; the last, its normal,
    turned to make a right-handed frame) and the first two over their spread (n, 3, 2): the
    local step's start (the compiled ``arap_rotations_kernel``)."""
    a, b = edges.T
    D = np.ascontiguousarray(rest[a] - rest[b])
    C = incidence @ (D[:, :, None] * D[:, None, :]).reshape(-1, 9)  # Σ over each vertex's edges
    lam, U = np.linalg.eigh(C.reshape(-1, 3, 3))  # ascending
    U = U[:, :, ::-1].copy()
    U[:, :, 2] = np.cross(U[:, :, 0], U[:, :, 1])
    spread = U[:, :, :2] / np.maximum(lam[:, ::-1][:, None, :2], UNDERFLOW_FLOOR)
    return D, np.ascontiguousarray(spread), np.ascontiguousarray(U)


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
        F = _checked("SurfaceRefiner", F, int(n_vertices), max_angle, iterations)
        for name, v in (("reach", reach), ("smoothness", smoothness), ("stiffness", stiffness)):
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"SurfaceRefiner: {name} must be > 0, found {v!r}")
        self.F, self.n = F, int(n_vertices)
        self.reach, self.cos = float(reach), float(np.cos(np.radians(max_angle)))
        self.alpha, self.beta, self.iterations = (
            float(smoothness),
            float(stiffness),
            int(iterations),
        )
        self.laplacian_ = _graph_laplacian(F, self.n)[1]

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

    def refine(
        self, V: np.ndarray, P: np.ndarray, NP: np.ndarray, *, key: int | None = None
    ) -> np.ndarray:
        """The surface ``V`` (n, 3) moved along its normals towards the observed points
        ``P`` (p, 3) with outward unit normals ``NP`` (p, 3), metres; returns (n, 3).
        ``key`` (the frame's number) is unused: each frame is refined on its own."""
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


def rotational_part(A: np.ndarray, R: np.ndarray, *, iterations: int = 4) -> np.ndarray:
    """The rotations nearest to matrices ``A`` (n, 3, 3), from rotations ``R`` (n, 3, 3).

    Müller et al. 2016, vectorised: each iteration turns ``R`` by the axis-angle
    ``ω = Σ_c r_c × a_c / |Σ_c r_c · a_c|`` (``r_c``, ``a_c`` the columns of ``R`` and
    ``A``), which maximises ``tr(Rᵀ A)`` (the rotation of the polar decomposition of ``A``
    where ``A`` is not singular) without a singular value decomposition. A few iterations
    from a nearby ``R`` suffice; from far away, more."""
    A = np.asarray(A, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    for _ in range(int(iterations)):
        num = cross(np.swapaxes(R, 1, 2), np.swapaxes(A, 1, 2)).sum(axis=1)  # Σ_c r_c × a_c
        den = np.abs(np.einsum("nij,nij->n", R, A)) + _TRACE_FLOOR
        R = so3_exp(num / den[:, None]) @ R
    return R


class ArapRefiner:
    """The as-rigid-as-possible refinement of a tracked surface towards observed points
    (module docstring): its vertices keep their place on the body.

    Parameters
    ----------
    rest : (n, 3) float64
        The surface's rest shape (the template's vertices), metres.
    F : (m, 3) int
        Its triangles (fixed over the track).
    data_weight : float
        ``λ``: weight of each vertex's target against its neighbourhood's rigidity.
    stiffness : float
        ``μ``: pull of every vertex towards the tracked surface.
    iterations : int
        Local and global steps (≥ 1); the targets are projected again before each.
    search_every : int
        The nearest compatible observed point of each vertex is searched for again every
        this many iterations (≥ 1); in between the same points are used, their tangent
        planes projected onto from where the vertices are.
    reach : float
        Metres: a vertex and an observed point further apart are not matched.
    max_angle : float
        Degrees: a vertex and an observed point whose normals differ more are not matched.
    anchor : {"previous", "rest"}
        The shape each neighbourhood keeps: the frame before's refined surface where that
        frame was the last one refined (else the rest shape), or always the rest shape.
    relaxation : float
        ``ω`` in [1, 2): each global step's over-relaxation (1: none).
    keep : float
        In (0, 1]: the share of a frame's refinement (its offset from the skin) that the
        next frame starts from and keeps as its shape; the rest is given back to the skin,
        so that what the chain of frames drifts is forgotten at that rate.

    Attributes
    ----------
    edges_ : (e, 2) int64, the surface's edges; ``factor_`` the factorised global step.
    """

    def __init__(
        self,
        rest: np.ndarray,
        F: np.ndarray,
        *,
        data_weight: float = 1.0,
        stiffness: float = 0.001,
        iterations: int = 20,
        reach: float = 0.05,
        max_angle: float = 60.0,
        search_every: int = 4,
        anchor: Literal["previous", "rest"] = "previous",
        relaxation: float = 1.8,
        keep: float = 0.95,
    ):
        check_choice("ArapRefiner", "anchor", anchor, ("previous", "rest"))
        if not (np.isfinite(relaxation) and 1.0 <= relaxation < 2.0):
            raise InputError(f"ArapRefiner: relaxation must be in [1, 2), found {relaxation!r}")
        if not (np.isfinite(keep) and 0.0 < keep <= 1.0):
            raise InputError(f"ArapRefiner: keep must be in (0, 1], found {keep!r}")
        self.anchor, self.omega, self.keep = anchor, float(relaxation), float(keep)
        rest = np.asarray(rest, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3 or not np.isfinite(rest).all():
            raise InputError(f"ArapRefiner: rest must be finite (n, 3), found {rest.shape}")
        n = len(rest)
        F = _checked("ArapRefiner", F, n, max_angle, iterations)
        for name, v in (("data_weight", data_weight), ("reach", reach)):
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"ArapRefiner: {name} must be > 0, found {v!r}")
        if not (np.isfinite(stiffness) and stiffness >= 0):
            raise InputError(f"ArapRefiner: stiffness must be ≥ 0, found {stiffness!r}")
        if isinstance(search_every, bool) or not (
            isinstance(search_every, int | np.integer) and search_every >= 1
        ):
            raise InputError(
                f"ArapRefiner: search_every must be an integer ≥ 1, found {search_every!r}"
            )
        self.search_every = int(search_every)
        self.F, self.n = F, n
        self.lam, self.mu, self.iterations = float(data_weight), float(stiffness), int(iterations)
        self.reach, self.cos = float(reach), float(np.cos(np.radians(max_angle)))
        self.edges_, L = _graph_laplacian(F, n)
        # (e, 3) rᵢ − rⱼ, and each rest neighbourhood's axes and spread (_rest_frames)
        self.incidence_ = _incidence(self.edges_, n)
        self.rest_edges_, self.spread_, self.axes_ = _rest_frames(
            rest, self.edges_, self.incidence_
        )
        self.factor_ = splu((L + (self.lam + self.mu) * sp.identity(n)).tocsc())
        #: (key, (n, 3) rest-frame refinement, (n, 3) refined surface) of the last keyed
        #: call (the refinement's share ``keep`` of it), or None
        self.last_: tuple[int, np.ndarray, np.ndarray] | None = None

    def rotations(self, V: np.ndarray, *, iterations: int = 4) -> np.ndarray:
        """The local step: each vertex's rotation (n, 3, 3) of its neighbourhood from rest
        to ``V`` (n, 3) (Eq. 6): the rotation maximising ``tr(Rᵀ Aᵢ)``,
        ``Aᵢ = Σ_j (vᵢ − vⱼ)(rᵢ − rⱼ)ᵀ``, from the one a rigid turn would have, by
        ``iterations`` of :func:`rotational_part` (compiled)."""
        rest = (self.rest_edges_, self.spread_, self.axes_)
        return self._rotations(V, rest, iterations=iterations)

    def _rotations(self, V: np.ndarray, rest: tuple, *, iterations: int = 4) -> np.ndarray:
        """:meth:`rotations` from the rest shape ``rest`` (:func:`_rest_frames`)."""
        from meshmocap.geometry._mesh_kernels import arap_rotations_kernel

        D, spread, axes = rest
        V = np.ascontiguousarray(V, dtype=np.float64)
        return arap_rotations_kernel(V, self.edges_, D, spread, axes, int(iterations))

    def refine(
        self, V: np.ndarray, P: np.ndarray, NP: np.ndarray, *, key: int | None = None
    ) -> np.ndarray:
        """The surface ``V`` (n, 3) refined towards the observed points ``P`` (p, 3) with
        outward unit normals ``NP`` (p, 3), metres; returns (n, 3).

        ``key``: the frame's number. Where the last call's key was the frame next to it
        (``key ± 1``), the vertices start where that frame's refinement left them with
        respect to the skin: its refinement ``Xᵢ − Vᵢ``, turned with each vertex's
        neighbourhood from the last frame's skin to this one's (the frame-to-frame anchor
        of what the skin cannot carry); with ``anchor="previous"`` that frame's refined
        surface is also the rest shape the neighbourhoods keep. None: from the skin alone,
        the template's rest shape kept."""
        from meshmocap.geometry._mesh_kernels import arap_rhs_kernel

        V = np.asarray(V, dtype=np.float64)
        P, NP = np.asarray(P, dtype=np.float64), np.asarray(NP, dtype=np.float64)
        # the skin's own turn of each vertex's neighbourhood from rest
        Rs = self.rotations(V)
        last = self.last_
        follows = key is not None and last is not None and abs(int(key) - last[0]) == 1
        S = V + (Rs @ last[1][:, :, None])[..., 0] if follows else V
        self.last_ = None
        if not len(P):
            return S.copy()
        tree = KDTree(P)
        rest = (self.rest_edges_, self.spread_, self.axes_)
        X, R = S.copy(), Rs
        if follows and self.anchor == "previous":  # the frame before's surface kept
            rest = _rest_frames(last[2], self.edges_, self.incidence_)
            R = self._rotations(X, rest)
        for it in range(self.iterations):
            if it % self.search_every == 0:  # each vertex's nearest compatible point
                N = vertex_normals(X, self.F)
                dist, j = tree.query(X, k=1)
                j = j.astype(np.int64)
                ok = (dist < self.reach) & (np.einsum("ij,ij->i", N, NP[j]) > self.cos)
            # targets: the vertex projected onto its observed point's tangent plane
            off = np.einsum("ij,ij->i", P[j] - X, NP[j])
            T = np.where(ok[:, None], X + off[:, None] * NP[j], S)
            # Eq. 9: Σ_j ½ (Rᵢ + Rⱼ)(rᵢ − rⱼ)
            rhs = arap_rhs_kernel(R, self.edges_, rest[0], self.n)
            Xn = self.factor_.solve(rhs + self.lam * T + self.mu * S)
            X = Xn + (self.omega - 1.0) * (Xn - X) if it else Xn  # over-relaxed
            R = self._rotations(X, rest)
        if key is not None:  # the refinement in the skin's rest frame, for the next frame
            kept = V + self.keep * (X - V)
            self.last_ = (int(key), np.einsum("nji,nj->ni", Rs, kept - V), kept)
        return X
