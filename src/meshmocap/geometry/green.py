"""3D Green coordinates of points in a closed triangle cage, and a precomputed deformer.

Green coordinates (Lipman, Levin & Cohen-Or, "Green Coordinates", SIGGRAPH 2008; "GC08"
below) write a point η inside a closed, outward-oriented triangle cage ``(V, F)`` as::

    η = Σ_i φ_i(η) v_i + Σ_j ψ_j(η) n_j        (GC08; cage-manifold-tracking Eq. (1))

with ``n_j`` the unit outward normal of face ``t_j``. They are Green's third identity
applied to the coordinate functions, with ``G(ξ, η) = −1 / (4π |ξ − η|)``::

    φ_i(η) = Σ_{j ∋ i} ∫_{t_j} Γ_i(ξ) ∂G/∂n(ξ, η) dσ     (double layer, Γ_i the hat of v_i)
    ψ_j(η) = −∫_{t_j} G(ξ, η) dσ = (1/4π) ∫_{t_j} dσ / |ξ − η|   (single layer, ≥ 0)

GC08 evaluates these integrals per face with its auxiliary routine GCTriInt (angles at
the foot of η on the face plane, arccos/atan/log of them). Here the same two integrals
are evaluated in an equivalent edge-wise closed form that vectorises over (points, faces,
3 edges) and needs no threshold: with, per face, ``h = n·(v_1 − η)`` (signed distance of
the face plane, > 0 seen from inside), ``Ω`` the signed solid angle of the face seen from
η, and per edge ``e`` (from ``a`` to ``b``) its outward in-plane normal ``ν_e``, its
in-plane distance ``d_e = ν_e·(a − η)`` and ``L_e = ∫_e ds/|ξ − η|``::

    4π ψ = Σ_e d_e L_e − h Ω                         (2D divergence theorem in the plane)
    4π φ_k = |e_k|/(2A) · (d_{e_k} Ω + h Σ_e (ν_{e_k}·ν_e) L_e)   (e_k: edge opposite v_k)

(``Γ_k`` is linear on the face: its value at the foot of η gives the Ω term, its gradient
``−ν_{e_k}|e_k|/(2A)`` times ``∫ ρ/r³ dσ = −Σ_e ν_e L_e`` the rest.) ``Ω`` is van
Oosterom & Strackee's atan2 formula and ``L_e = log((r_a + r_b + ℓ)/(r_a + r_b − ℓ))``
with the denominator rewritten ``2|a×b|² / ((r_a r_b − a·b)(r_a + r_b + ℓ))`` where it
would cancel. No threshold is needed (GC08 skips faces with ``|w| < ε``): the jump of Ω
across a face is multiplied by ``h`` or by the continuous foot barycentrics, so values are
continuous through the faces. Σ_i φ_i equals the winding number: 1 inside, 0 outside.

Accuracy near the cage. Next to a face interior points are as accurate as central ones;
within ρ of a cage edge or vertex the solid angles lose ~1e-16 · size / ρ (about
1e-10 at 1 µm of a 1 m cage). Points within 1e-7 × the cage diameter of a face (on the
cage, where Ω is undefined) are evaluated 1e-7 × diameter inside that face and carried
back by the continuation below: they get the interior limit to ~1e-6, finite everywhere.

Exterior points. Outside the cage the raw integrals reproduce 0, not η. With
``exterior="extend"`` (default) a point whose winding number is below ½ gets the
analytic continuation of the interior coordinates through its nearest face ``t``
(GC08 "exterior of the cage"; Lipman & Levin 2010): writing ``η = Σ_k α_k v_k + α_4 n_t``
(``α_k`` the barycentrics of the foot of η on ``t``, ``α_4`` its height above ``t``),
``φ_{t_k} += α_k`` and ``ψ_t += α_4``. The rest pose is then reproduced everywhere and
the coordinates are continuous across ``t``; a deformed point outside follows ``t``'s
continuation, which is smooth only within the region nearest to ``t`` (meant for template
vertices slightly outside the cage, not for far points).

Deformation (cage-manifold-tracking Eq. (1) with GC08's 3D stretch factor)::

    x' = Σ_i φ_i v'_i + Σ_j ψ_j s_j n'_j,
    s_j = sqrt(|u'|²|v|² − 2(u'·v')(u·v) + |v'|²|u|²) / (sqrt(8) area_j)

``u, v`` the face's edge vectors ``v_2 − v_1, v_3 − v_1`` at rest, ``u', v'`` deformed.
At rest ``s_j = 1`` (the numerator is ``2|u×v|² = 8 area²``); under a similarity of
scale ``k``, ``s_j = k`` and ``x' = k R x + t`` exactly.

Frames and units: world frame (Z up), metres; coordinates are unitless (φ) or metres (ψ).

References
----------
- Y. Lipman, D. Levin, D. Cohen-Or, *Green coordinates*, ACM Transactions on Graphics
  27(3) (SIGGRAPH 2008). https://doi.org/10.1145/1360612.1360677
- Y. Lipman, D. Levin, *Derivation and analysis of Green coordinates*, Computational
  Methods and Function Theory 10(1):167–188, 2010.
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy import sparse

from meshmocap._tolerances import RELATIVE_DEGENERATE
from meshmocap._validate import check_choice
from meshmocap.errors import InputError, MeshError
from meshmocap.geometry.mesh import mesh_problems, signed_volume
from meshmocap.geometry.rotations import cross, skew

Exterior = Literal["extend", "raw", "raise"]
_EXTERIOR = ("extend", "raw", "raise")
_PAIRS_PER_CHUNK = 1 << 15  # (point, face) pairs per chunk: 256 kB per temporary (L2)
#: Smallest ``s − ℓ`` an edge's log integral takes (0 on the cage's edge line: a finite log).
_GAP_FLOOR = 1e-290
_ON_CAGE = 1e-7  # points closer than this × cage diameter to a face count as on the cage


# ------------------------------------------------------------------------------ checks
def _check_cage(func: str, cage_V, cage_F) -> tuple[np.ndarray, np.ndarray]:
    V = np.array(cage_V, dtype=np.float64)  # own copies: the deformer keeps them
    F = np.array(cage_F)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) < 4 or not np.all(np.isfinite(V)):
        raise InputError(f"{func}: cage_V must be finite with shape (n, 3), n ≥ 4, found {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) < 4 or not np.issubdtype(F.dtype, np.integer):
        raise InputError(
            f"{func}: cage_F must be (m, 3) integers with m ≥ 4, found {F.shape} {F.dtype}"
        )
    F = F.astype(np.int64)
    problems = mesh_problems(V, F)
    if problems:
        raise MeshError(f"{func}: the cage must be a closed 2-manifold: {'; '.join(problems)}")
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    if len(np.unique(directed, axis=0)) != len(directed):
        raise MeshError(f"{func}: cage faces are not consistently oriented")
    if np.any(np.bincount(F.ravel(), minlength=len(V)) == 0):
        raise MeshError(f"{func}: cage_V has vertices used by no face")
    area2 = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    flat = area2 <= RELATIVE_DEGENERATE * np.ptp(V, axis=0).max() ** 2
    if flat.any():
        raise MeshError(f"{func}: {int(flat.sum())} cage faces have (near) zero area")
    if signed_volume(V, F) <= 0:
        raise MeshError(f"{func}: cage faces must be oriented outward (signed volume ≤ 0)")
    return V, F


def _check_points(func: str, name: str, points, n_cols: int = 3) -> np.ndarray:
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != n_cols:
        raise InputError(f"{func}: {name} must have shape (n, {n_cols}), found {P.shape}")
    if not np.all(np.isfinite(P)):
        raise InputError(f"{func}: {name} contains NaN or infinite values")
    return P


# ------------------------------------------------------------------------------ kernel
def _dot(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """Dot product of vectors given as lists of 3 broadcastable component arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


class _Faces:
    """Per-face constants of a cage (m faces), as component lists broadcasting on (c, m).

    ``C[k][i]``: component ``i`` of corner ``k``; ``E[k]``: edge ``k`` (``v_k → v_{k+1}``);
    ``n``: unit outward normal; ``nu[k]``: outward in-plane normal of edge ``k``.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray) -> None:
        C = np.stack([V[F[:, k]] for k in range(3)])  # corners (3, m, 3)
        E = np.stack([C[(k + 1) % 3] - C[k] for k in range(3)])  # edge k: v_k → v_{k+1}
        N = np.cross(E[0], -E[2])
        self.area2 = np.linalg.norm(N, axis=1)  # 2 × area, (m,)
        n = N / self.area2[:, None]
        self.length = np.linalg.norm(E, axis=2)  # (3, m)
        nu = np.cross(E, n) / self.length[..., None]  # counter-clockwise edges: e × n points out
        # Γ_k = w_k d_{k+1} and ∇Γ_k = −w_k ν_{k+1} (edge k + 1 is opposite v_k);
        # the 1/(4π) of G is folded in here.
        self.w = self.length[[1, 2, 0]] / self.area2 / (4.0 * np.pi)  # (3, m)
        self.M = np.einsum("kfi,efi->kef", nu[[1, 2, 0]], nu)  # ν_{k+1}·ν_e, (3, 3, m)
        self.two_l2 = 2.0 * self.length**2
        self.C = [[C[k][:, i] for i in range(3)] for k in range(3)]
        self.E = [[E[k][:, i] for i in range(3)] for k in range(3)]
        self.n = [n[:, i] for i in range(3)]
        self.nu = [[nu[k][:, i] for i in range(3)] for k in range(3)]


def _chunk(P: np.ndarray, fc: _Faces) -> tuple[np.ndarray, ...]:
    """Per-face Green coordinates of points ``P`` (c, 3), cage-centred.

    Returns ``phi_f`` (3, c, m) (face ``j``'s share of φ at its corner ``k``), ``psi``
    (c, m), the heights ``h`` (c, m) and the edge distances ``d`` (3, c, m).
    """
    # Relative corners a_k = v_k − η by direct subtraction (exact to rounding relative to
    # |a_k|, which keeps points next to a vertex or an edge accurate), component-wise.
    A = [[fc.C[k][i] - P[:, i, None] for i in range(3)] for k in range(3)]
    r = [np.sqrt(_dot(a, a)) for a in A]
    D = [_dot(A[k], A[(k + 1) % 3]) for k in range(3)]  # a_k·a_{k+1}
    h = _dot(fc.n, A[0])  # n·(v_0 − η) > 0 seen from inside
    d = np.stack([_dot(fc.nu[k], A[k]) for k in range(3)])  # ν_k·(v_k − η)
    h2 = h * h
    # van Oosterom & Strackee 1983: tan(Ω/2) = [a b c] / (abc + (a·b)c + (b·c)a + (c·a)b);
    # the triple product [a b c] is exactly 2A·h.
    den = r[0] * r[1] * r[2] + D[0] * r[2] + D[1] * r[0] + D[2] * r[1]
    omega = 2.0 * np.arctan2(fc.area2 * h, den)  # signed solid angle of the face
    L = np.empty_like(d)
    for k in range(3):  # L_k = ∫_{edge k} ds / |ξ − η|
        k1 = (k + 1) % 3
        s = r[k] + r[k1]
        sp = s + fc.length[k]
        rab = r[k] * r[k1] - D[k]  # ≥ r_a r_b when the angle at η is obtuse
        obtuse = D[k] < 0
        # L = log((s + ℓ)/(s − ℓ)); beside the edge s − ℓ cancels, so there use
        # s − ℓ = 2|a×b|²/((r_a r_b − a·b)(s + ℓ)) with |a×b|² = ℓ²(h² + d²)
        stable = fc.two_l2[k] * (h2 + d[k] * d[k]) / (np.where(obtuse, rab, 1.0) * sp)
        gap = np.maximum(np.where(obtuse, stable, s - fc.length[k]), _GAP_FLOOR)  # 0 on the cage
        L[k] = np.log(sp / gap)
    # 4π ψ = Σ_e d_e L_e − h Ω  (single-layer potential of the face, GC08's ψ_j)
    psi = (d[0] * L[0] + d[1] * L[1] + d[2] * L[2] - h * omega) / (4.0 * np.pi)
    # 4π φ_k = (|e_{k+1}|/2A)(d_{k+1} Ω + h Σ_e (ν_{k+1}·ν_e) L_e)  (double layer, GC08's φ_i)
    ML = np.einsum("kef,ecf->kcf", fc.M, L)
    phi_f = fc.w[:, None, :] * (d[[1, 2, 0]] * omega + h * ML)
    return phi_f, psi, h, d


def _nearest_faces(P: np.ndarray, h: np.ndarray, d: np.ndarray, fc: _Faces) -> np.ndarray:
    """Index (c,) of the face nearest to each point ``P`` (c, 3), given its ``h``, ``d``."""
    A = [[fc.C[k][i] - P[:, i, None] for i in range(3)] for k in range(3)]
    seg = np.full(h.shape, np.inf)  # squared distance to the face's boundary
    for k in range(3):
        t = np.clip(-_dot(A[k], fc.E[k]) / fc.length[k] ** 2, 0.0, 1.0)
        q = [A[k][i] + t * fc.E[k][i] for i in range(3)]
        seg = np.minimum(seg, _dot(q, q))
    foot_inside = np.all(d >= 0, axis=0)  # the foot of η lies in the face
    return np.argmin(np.where(foot_inside, h * h, seg), axis=1)


def _continue(phi, psi, rows, j, F, fc, dd, dh) -> None:
    """Add to rows ``rows`` the continuation through their faces ``j`` (GC08 exterior;
    Lipman & Levin 2010) of a change ``dd`` (3, r) of the edge distances and ``dh`` (r,)
    of the height: writing η = Σ_k α_k v_k + α_4 n_j, α_k = Γ_k(foot) = 4π w_k d_{k+1}
    and α_4 = −h, so φ_{j_k} += Δα_k and ψ_j += Δα_4."""
    for k in range(3):
        phi[rows, F[j, k]] += 4.0 * np.pi * fc.w[k, j] * dd[(k + 1) % 3]
    psi[rows, j] -= dh


def _coordinates(
    P: np.ndarray,
    V: np.ndarray,
    F: np.ndarray,
    exterior: str,
    chunk_size: int | None,
    out: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Green coordinates of ``P`` (n, 3) written chunk by chunk into ``out`` (nv + nf, n)
    (φ rows, then ψ rows; any float dtype; allocated float64 when None), and which points
    lie outside (n,). Memory: ``out`` and one chunk's temporaries, whatever ``n``."""
    centre = V.mean(axis=0)  # coordinates are translation invariant; centring keeps
    P, V = P - centre, V - centre  # the face constants accurate far from the origin
    fc = _Faces(V, F)
    n, nv, nf = len(P), len(V), len(F)
    band = _ON_CAGE * np.linalg.norm(np.ptp(V, axis=0))
    # scatter (corner k of face j) -> vertex F[j, k] as one dense product
    S = np.zeros((3 * nf, nv))
    S[np.arange(3 * nf), F.T.ravel()] = 1.0

    def scatter(phi_f: np.ndarray) -> np.ndarray:
        return phi_f.transpose(1, 0, 2).reshape(phi_f.shape[1], -1) @ S

    out = np.empty((nv + nf, n)) if out is None else out
    outside = np.zeros(n, dtype=bool)
    step = chunk_size or max(1, _PAIRS_PER_CHUNK // nf)
    for lo in range(0, n, step):
        Pc = P[lo : lo + step]
        phi_f, psi, h, d = _chunk(Pc, fc)
        phi = scatter(phi_f)  # (m, nv), this chunk's rows
        # On the cage (within `band` of a face) the solid angles are ill-conditioned:
        # evaluate at a point `band` inside face j instead and continue through j.
        near = (np.abs(h) <= band) & (d.min(axis=0) >= -band)
        on = near.any(axis=1)
        if on.any():
            idx = np.flatnonzero(on)
            miss = np.minimum(d[:, idx], 0.0)
            score = np.where(near[idx], h[idx] ** 2 + np.sum(miss * miss, axis=0), np.inf)
            j = np.argmin(score, axis=1)
            nj = np.stack(fc.n, axis=1)[j]
            foot = Pc[idx] + h[idx, j][:, None] * nj
            g = np.stack([sum(fc.C[k][i][j] for k in range(3)) / 3 for i in range(3)], axis=1)
            margin = fc.area2[j] / (3.0 * fc.length[:, j].max(axis=0))  # in-radius-like
            tau = (2.0 * band / (margin + band))[:, None]
            inner = g + (1.0 - tau) * (foot - g) - band * nj  # ≥ band inside face j
            phi_f, psi_i, h_i, d_i = _chunk(inner, fc)
            phi[idx], psi[idx] = scatter(phi_f), psi_i
            r = np.arange(len(idx))
            _continue(phi, psi, idx, j, F, fc, d[:, idx, j] - d_i[:, r, j], h[idx, j] - h_i[r, j])
        ext = (phi.sum(axis=1) < 0.5) & ~on  # winding number: 1 inside, 0 outside
        outside[lo : lo + step] = ext
        if exterior == "extend" and ext.any():
            idx = np.flatnonzero(ext)
            j = _nearest_faces(Pc[idx], h[idx], d[:, idx], fc)
            _continue(phi, psi, idx, j, F, fc, d[:, idx, j], h[idx, j])
        out[:nv, lo : lo + step] = phi.T
        out[nv:, lo : lo + step] = psi.T
    if exterior == "raise" and outside.any():
        first = int(np.flatnonzero(outside)[0])
        raise InputError(
            f"green_coordinates: {int(outside.sum())} points lie outside the cage "
            f"(first: {first} at {(P[first] + centre).tolist()}); use exterior='extend'"
        )
    return out, outside


def green_coordinates(
    points: np.ndarray,
    cage_V: np.ndarray,
    cage_F: np.ndarray,
    *,
    exterior: Exterior = "extend",
    chunk_size: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the 3D Green coordinates of points w.r.t. a closed triangle cage.

    Parameters
    ----------
    points : (n, 3) float64
        Points to encode, metres, world frame (Z up); meant to lie inside the cage.
    cage_V : (nv, 3) float64
        Cage vertices, metres, world frame.
    cage_F : (nf, 3) int
        Cage triangles, counter-clockwise seen from outside (outward normals); the cage
        must be a closed, consistently oriented 2-manifold.
    exterior : {"extend", "raw", "raise"}
        Points outside the cage (winding number < ½): ``"extend"`` continues the
        coordinates analytically through the nearest face (rest pose reproduced, see the
        module notes); ``"raw"`` returns the plain Green integrals (which reproduce 0
        there, Σ φ = 0); ``"raise"`` raises :class:`InputError`.
    chunk_size : int, optional
        Points per vectorised chunk (default 32,768 // nf, which keeps the temporaries
        in L2); the temporaries take about ``60 × 8 × chunk_size × nf`` bytes, beside the
        ``8 × n × (nv + nf)`` of the result. Results do not depend on it.

    Returns
    -------
    phi : (n, nv) float64
        Vertex coordinates φ (unitless); each row sums to 1 (inside and extended points).
    psi : (n, nf) float64
        Face-normal coordinates ψ, metres; ≥ 0 inside.

    Raises
    ------
    InputError
        Wrong shapes, non-finite values, an unknown option, or points outside the cage
        with ``exterior="raise"``.
    MeshError
        The cage is open, non-manifold, inconsistently or inward oriented, or has
        degenerate faces.

    Notes
    -----
    ``points[p] == phi[p] @ cage_V + psi[p] @ n`` to rounding (about 1e-14 m for a
    1 m cage; see the module notes near edges) with ``n`` the unit outward face normals.
    Cost: O(n · nf), ~130 array operations per (point, face) pair (timings:
    ``benchmarks/bench_green.py``).
    """
    func = "green_coordinates"
    check_choice(func, "exterior", exterior, _EXTERIOR)
    V, F = _check_cage(func, cage_V, cage_F)
    P = _check_points(func, "points", points)
    if chunk_size is not None and (not isinstance(chunk_size, int | np.integer) or chunk_size < 1):
        raise InputError(f"{func}: chunk_size must be a positive integer, found {chunk_size!r}")
    GT, _ = _coordinates(P, V, F, exterior, chunk_size)
    return GT[: len(V)].T, GT[len(V) :].T


# ------------------------------------------------------------------------------ deformer
class GreenDeformer:
    """Green-coordinate cage deformation with precomputed coordinates (a solver object).

    Build once per (rest cage, point set); then :meth:`deform` maps a deformed cage to
    the deformed points with one matrix product, cage-manifold-tracking Eq. (1) with
    GC08's per-face stretch factors.

    Parameters
    ----------
    cage_V : (nv, 3) float64
        Rest cage vertices, metres, world frame (Z up).
    cage_F : (nf, 3) int
        Cage triangles, outward (counter-clockwise seen from outside), closed manifold.
    points : (n, 3) float64
        Points carried by the cage (template vertices, joints), metres, world frame.
    exterior : {"extend", "raw", "raise"}
        Handling of points outside the cage, see :func:`green_coordinates`.
    dtype : {numpy.float64, numpy.float32}
        Storage of the coordinates: ``(nv + nf) × n`` numbers, written chunk by chunk
        (no full-size temporary: memory is the storage plus one chunk's temporaries).
        float32 halves the memory and the traffic of :meth:`deform` (faster for large
        point sets) at ~2e-6 relative accuracy (micrometres on a human-sized cage); the
        derivatives compute in float64 from the stored coordinates.
    chunk_size : int, optional
        See :func:`green_coordinates`.

    Attributes
    ----------
    phi_ : (n, nv) float64 or float32
        Vertex coordinates (a view of the storage). With normals and stretch factors held
        fixed this is also the Jacobian: ``d x'[p, a] / d v'[i, b] = phi_[p, i] δ_ab``.
    psi_ : (n, nf) float64 or float32
        Face-normal coordinates, metres.
    outside_ : (n,) bool
        Points outside the rest cage (coordinates extended or raw); points on the cage
        (within 1e-7 × its diameter) count as inside.
    cage_F_ : (nf, 3) int64
        Cage faces. ``rest_V_`` (nv, 3): rest cage. ``rest_u_``, ``rest_v_`` (nf, 3):
        rest edge vectors ``v_2 − v_1``, ``v_3 − v_1``; ``rest_area_`` (nf,) m².

    Notes
    -----
    Derivatives for trackers (normals and stretch factors included): :meth:`vjp` (gradient
    of a scalar energy of the points, what Eq. (6) of the cage paper needs),
    :meth:`pointwise_vjp` (one per point: Gauss–Newton rows), :meth:`jvp` (directional,
    batched) and :meth:`jacobian` (dense ``(n, 3, nv, 3)``, for small sets such as joints).
    """

    def __init__(
        self,
        cage_V: np.ndarray,
        cage_F: np.ndarray,
        points: np.ndarray,
        *,
        exterior: Exterior = "extend",
        dtype: type = np.float64,
        chunk_size: int | None = None,
    ) -> None:
        func = "GreenDeformer"
        check_choice(func, "exterior", exterior, _EXTERIOR)
        if np.dtype(dtype) not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise InputError(f"{func}: dtype must be float64 or float32, found {dtype!r}")
        V, F = _check_cage(func, cage_V, cage_F)
        P = _check_points(func, "points", points)
        # coordinates stored transposed, (nv + nf, n): the product B.T @ G_T is the
        # fastest layout for a 3-column right-hand side; written chunk by chunk in their
        # storage type (memory: the coordinates and one chunk, module notes)
        self._GT = np.empty((len(V) + len(F), len(P)), dtype=dtype)
        _, outside = _coordinates(P, V, F, exterior, chunk_size, self._GT)
        self.phi_, self.psi_ = self._GT[: len(V)].T, self._GT[len(V) :].T  # views
        self.outside_, self.cage_F_, self.rest_V_ = outside, F, V
        self.rest_u_, self.rest_v_ = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
        self.rest_area_ = 0.5 * np.linalg.norm(np.cross(self.rest_u_, self.rest_v_), axis=1)
        uu = np.einsum("ij,ij->i", self.rest_u_, self.rest_u_)
        self._a = 1.0 / np.sqrt(uu)  # 1/|u|
        self._b = np.sqrt(uu) / (2.0 * self.rest_area_)  # |u|/(2A)
        self._c = np.einsum("ij,ij->i", self.rest_u_, self.rest_v_) / uu  # u·v/|u|²
        self._f = [np.ascontiguousarray(F[:, k], dtype=np.intp) for k in range(3)]
        # CSR pattern of pointwise_vjp's (3 nv, 3 nf) matrix, entry (j, k, a, b) (corner k of
        # face j) at row 3 F[j, k] + b, column 3 j + a; the order sorts them by row
        rows, cols = (
            np.broadcast_to(x, (len(F), 3, 3, 3)).ravel()
            for x in (
                3 * F[:, :, None, None] + np.arange(3),
                3 * np.arange(len(F))[:, None, None, None] + np.arange(3)[:, None],
            )
        )
        self._corner_order = np.lexsort((cols, rows))
        indptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=3 * len(V)))]
        self._corner_csr = (cols[self._corner_order].astype(np.int32), indptr.astype(np.int32))

    @property
    def n_points(self) -> int:
        """Number of points carried by the cage."""
        return self.phi_.shape[0]

    def _apply(self, M: np.ndarray) -> np.ndarray:
        """``phi_ @ M[:nv] + psi_ @ M[nv:]`` in float64, (k, n, 3), for M (k, nv + nf, 3)."""
        k, m, _ = M.shape
        if self._GT.dtype == np.float64:  # (3k, m) @ (m, n): the fast layout
            X = M.transpose(0, 2, 1).reshape(3 * k, m) @ self._GT
            return X.reshape(k, 3, -1).transpose(0, 2, 1)
        nv = len(self.rest_V_)
        return self.phi_ @ M[:, :nv] + self.psi_ @ M[:, nv:]

    def _apply_t(self, G: np.ndarray) -> np.ndarray:
        """``[phi_ | psi_]ᵀ @ G`` in float64, (nv + nf, 3), for G (n, 3)."""
        if self._GT.dtype == np.float64:
            return self._GT @ G
        return np.vstack([self.phi_.T @ G, self.psi_.T @ G])

    def _cage(self, func: str, cage_V_new, *, batch: bool = False) -> np.ndarray:
        V = np.asarray(cage_V_new, dtype=np.float64)
        ok = V.shape[-2:] == self.rest_V_.shape and (V.ndim == 2 or (batch and V.ndim == 3))
        if not ok:
            want = f"{self.rest_V_.shape}" + (" or (k, *that)" if batch else "")
            raise InputError(
                f"GreenDeformer.{func}: cage_V_new must have shape {want}, found {V.shape}"
            )
        if not np.all(np.isfinite(V)):
            raise InputError(f"GreenDeformer.{func}: cage_V_new contains NaN or infinite values")
        return V

    def _grads(self, func: str, grad_points) -> np.ndarray:
        G = _check_points(f"GreenDeformer.{func}", "grad_points", grad_points)
        if len(G) != self.n_points:
            raise InputError(
                f"GreenDeformer.{func}: grad_points must have shape "
                f"({self.n_points}, 3), found {G.shape}"
            )
        return G

    def _faces(self, V: np.ndarray) -> tuple[np.ndarray, ...]:
        """Deformed edges u', v', |u'×v'|, unit normals n', the 2D map columns J1, J2, s;
        ``V`` is (nv, 3) or (k, nv, 3), outputs carry the same leading axis."""
        f0, f1, f2 = self._f
        u, v = V[..., f1, :] - V[..., f0, :], V[..., f2, :] - V[..., f0, :]
        c = cross(u, v)
        cn = np.sqrt(np.add.reduce(c * c, axis=-1))  # np.linalg.norm, without its overhead
        n = c / np.where(cn > 0, cn, np.inf)[..., None]  # 0 on a collapsed face (c = 0)
        # GC08 stretch s = sqrt(|u'|²|v|² − 2(u'·v')(u·v) + |v'|²|u|²) / (sqrt(8) area),
        # evaluated as ‖J‖_F/√2 (the same number: the numerator is 4 area² ‖J‖_F²) with J
        # the face's linear map in a rest orthonormal frame, J = [u'/|u|, (v' − c u')|u|/2A],
        # c = u·v/|u|²; this avoids the cancellation of the expanded form on thin faces.
        J1 = u * self._a[:, None]
        J2 = (v - self._c[:, None] * u) * self._b[:, None]
        s = np.sqrt(0.5 * (np.add.reduce(J1 * J1, axis=-1) + np.add.reduce(J2 * J2, axis=-1)))
        return u, v, cn, n, J1, J2, s

    def stretch_factors(self, cage_V_new: np.ndarray) -> np.ndarray:
        """Return the stretch factors ``s_j``, (nf,) or (k, nf) (1 at rest, k under scale k)."""
        return self._faces(self._cage("stretch_factors", cage_V_new, batch=True))[-1]

    def deform(self, cage_V_new: np.ndarray) -> np.ndarray:
        """Return the deformed points ``x' = Σ φ_i v'_i + Σ ψ_j s_j n'_j`` (Eq. (1)).

        Parameters
        ----------
        cage_V_new : (nv, 3) or (k, nv, 3) float64
            Deformed cage vertices, metres, world frame (same faces as at rest). A batch
            of ``k`` cages costs little more than one (the coordinates are read once).

        Returns
        -------
        (n, 3) or (k, n, 3) float64
            Deformed points, metres, world frame.
        """
        V = self._cage("deform", cage_V_new, batch=True)
        _, _, _, n, _, _, s = self._faces(V)
        k, nv = (1 if V.ndim == 2 else len(V)), V.shape[-2]
        B = np.empty((k, 3, self._GT.shape[0]), dtype=self._GT.dtype)
        B[:, :, :nv] = V.reshape(k, nv, 3).transpose(0, 2, 1)
        B[:, :, nv:] = (n * s[..., None]).reshape(k, -1, 3).transpose(0, 2, 1)  # s_j n'_j
        if k == 1 and B.dtype == np.float64:  # 3 gemv: dgemm on 3 rows packs G first
            X = np.stack([b @ self._GT for b in B[0]])[None]
        else:
            X = (B.reshape(3 * k, -1) @ self._GT).reshape(k, 3, -1)
        X = np.ascontiguousarray(X.transpose(0, 2, 1), dtype=np.float64)  # Eq. (1)
        return X[0] if V.ndim == 2 else X

    def _face_terms(self, V: np.ndarray) -> tuple[np.ndarray, ...]:
        """The derivatives of f_j = s_j n'_j (V (nv, 3)) as rank one plus cross product:
        ``df = n' (a_u·du' + a_v·dv') + k u' × dv' − k v' × du'`` with ``k = s/|u'×v'|``.
        Returns n', a_u, a_v, k u', k v', each (nf, 3)."""
        u, v, cn, n, J1, J2, s = self._faces(V)
        # s² = (|J1|² + |J2|²)/2, J1 = a u', J2 = b (v' − c u'):
        # ds/du' = (a J1 − c b J2)/(2s), ds/dv' = b J2/(2s)
        inv2s = 0.5 / np.where(s > 0, s, np.inf)[:, None]  # faster than np.divide(where=)
        dsu = (self._a[:, None] * J1 - (self._c * self._b)[:, None] * J2) * inv2s
        dsv = self._b[:, None] * J2 * inv2s
        # dn' = (I − n'n'ᵀ) dc / |c|, dc = du' × v' + u' × dv', (I − n'n'ᵀ)[x]× = [x]× −
        # n'(n'×x)ᵀ: s dn' = k (n' (n'×v')·du' − v' × du' − n' (n'×u')·dv' + u' × dv')
        k = (s / np.where(cn > 0, cn, np.inf))[:, None]
        ku, kv = k * u, k * v
        return n, dsu + cross(n, kv), dsv - cross(n, ku), ku, kv

    def _face_blocks(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives (nf, 3, 3) of f_j = s_j n'_j w.r.t. the edges u' and v' (rows: f)."""
        n, au, av, ku, kv = self._face_terms(V)
        return n[:, :, None] * au[:, None, :] - skew(kv), n[:, :, None] * av[:, None, :] + skew(ku)

    def jvp(self, cage_V_new: np.ndarray, dV: np.ndarray) -> np.ndarray:
        """Return d x' (n, 3), the derivative of :meth:`deform` at ``cage_V_new`` along ``dV``.

        ``dV`` : (nv, 3) float64, a cage-vertex displacement (metres), or (k, nv, 3): k
        directions at once, result (k, n, 3). Normals and stretch factors are exact.
        """
        V = self._cage("jvp", cage_V_new)
        dV = np.asarray(dV, dtype=np.float64)
        if dV.shape[-2:] != V.shape or dV.ndim not in (2, 3) or not np.all(np.isfinite(dV)):
            raise InputError(
                f"GreenDeformer.jvp: dV must be finite with shape {V.shape} or "
                f"(k, *that), found {dV.shape}"
            )
        f0, f1, f2 = self._f
        n, au, av, ku, kv = self._face_terms(V)
        D = dV.reshape(-1, *V.shape)
        du, dv = D[:, f1] - D[:, f0], D[:, f2] - D[:, f0]
        dot = np.add.reduce(au * du + av * dv, axis=-1)
        df = n * dot[..., None] + cross(ku, dv) - cross(kv, du)
        X = self._apply(np.concatenate([D, df], axis=1))
        return X[0] if dV.ndim == 2 else X

    def vjp(self, cage_V_new: np.ndarray, grad_points: np.ndarray) -> np.ndarray:
        """Return dE/dV' (nv, 3) given dE/dx' (n, 3) at ``cage_V_new`` (chain rule, Eq. (6)).

        Exact: includes the derivatives of the normals and stretch factors.
        """
        V, G = self._cage("vjp", cage_V_new), self._grads("vjp", grad_points)
        F, nv = self.cage_F_, len(V)
        n, au, av, ku, kv = self._face_terms(V)
        both = self._apply_t(G)
        out, gf = both[:nv], both[nv:]  # dE/dV' through φ, and dE/df_j, f_j = s_j n'_j
        ng = np.add.reduce(n * gf, axis=1)[:, None]
        gu, gv = au * ng + cross(kv, gf), av * ng - cross(ku, gf)  # (df/du')ᵀ gf, …
        corner = np.concatenate([-(gu + gv), gu, gv])  # rows for F[:, 0], F[:, 1], F[:, 2]
        idx = (3 * F.T.reshape(-1, 1) + np.arange(3)).ravel()  # (vertex, coordinate) bins
        return out + np.bincount(idx, corner.ravel(), minlength=3 * nv).reshape(nv, 3)

    def pointwise_vjp(self, cage_V_new: np.ndarray, grad_points: np.ndarray) -> np.ndarray:
        """Return ``W`` (n, nv, 3), ``W[p] = d(grad_points[p] · x'_p) / dV'``: each point's own
        :meth:`vjp` (``W.sum(0) == vjp``; normals and stretch factors included), i.e. the
        Jacobian of n residuals ``g_p · x'_p`` (Gauss–Newton, Eq. (6) of the cage paper)
        without the dense :meth:`jacobian`."""
        V = self._cage("pointwise_vjp", cage_V_new)
        G = self._grads("pointwise_vjp", grad_points)
        nv, nf = len(V), len(self.cage_F_)
        GT = np.ascontiguousarray(G.T)
        W = self.phi_.T[:, None, :] * GT  # (nv, 3, n): through φ
        Pg = (self.psi_.T[:, None, :] * GT).reshape(3 * nf, -1)  # ψ_pj g_pa, rows (j, a)
        # through f_j = s_j n'_j: corner k of face j gets Σ_a Pg[(j, a)] C_jk[a, b] (C_j0 =
        # −(Bu + Bv), C_j1 = Bu, C_j2 = Bv), summed per vertex by one sparse product (its
        # pattern precomputed: no sorting per call)
        Bu, Bv = self._face_blocks(V)
        C = np.stack([-(Bu + Bv), Bu, Bv], axis=1).ravel()[self._corner_order]
        CT = sparse.csr_matrix((C, *self._corner_csr), shape=(3 * nv, 3 * nf))
        W += (CT @ Pg).reshape(nv, 3, -1)
        return W.transpose(2, 0, 1)

    def jacobian(self, cage_V_new: np.ndarray) -> np.ndarray:
        """Return the dense Jacobian ``J[p, a, i, b] = d x'[p, a] / d v'[i, b]``, (n, 3, nv, 3).

        Memory ``72 · n · nv`` bytes: meant for small point sets (joints); for the template
        use :meth:`vjp` / :meth:`jvp`, or ``phi_`` when normals are held fixed.
        """
        V = self._cage("jacobian", cage_V_new)
        F, nv, nf = self.cage_F_, len(V), len(self.cage_F_)
        Bu, Bv = self._face_blocks(V)
        E = np.zeros((nf, 3, nv, 3))  # d f_j / d v'_i
        rows = np.arange(nf)
        for k, B in enumerate((-(Bu + Bv), Bu, Bv)):
            np.add.at(E, (rows, slice(None), F[:, k]), B)
        J = (self.psi_ @ E.reshape(nf, -1)).reshape(self.n_points, 3, nv, 3)
        for a in range(3):
            J[:, a, :, a] += self.phi_
        return J
