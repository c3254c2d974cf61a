"""Tests for meshmocap.geometry.green: 3D Green coordinates and the cage deformer.

Tolerances. Coordinates are sums of O(1) terms in float64, so points a unit-size cage
reproduces are exact to ~1e-14; 1e-9 leaves five orders of margin for the one known loss
(near a cage edge or vertex at distance δ the solid angle is evaluated to ~1e-16/δ).
Quadrature references use 60×60 Gauss–Legendre points on smooth integrands (points
≥ 0.1 from the face): ~1e-13, checked at 1e-10. Finite differences are central with step
1e-6 (truncation ~1e-12 × third derivative, rounding ~1e-10): checked at 1e-6 relative.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from meshmocap.errors import InputError, MeshError
from meshmocap.geometry.green import GreenDeformer, green_coordinates

CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
CUBE_F = np.array(
    [
        [0, 3, 2],
        [0, 1, 3],
        [4, 7, 5],
        [4, 6, 7],
        [0, 5, 1],
        [0, 4, 5],
        [2, 7, 6],
        [2, 3, 7],
        [0, 6, 4],
        [0, 2, 6],
        [1, 7, 3],
        [1, 5, 7],
    ]
)
OCTA_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTA_F = np.array(
    [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
)


def _normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def _star_cage(n: int, bumps: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Closed cage over ``n`` random directions, radius 1 + bumps·f(direction), outward."""
    u = np.random.default_rng(seed).normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    F = ConvexHull(u).simplices.copy()
    flip = np.einsum("ij,ij->i", _normals(u, F), u[F].mean(axis=1)) < 0
    F[flip] = F[flip][:, ::-1]
    radius = 1.0 + bumps * np.sin(3 * u[:, 0]) * np.cos(2 * u[:, 1])
    return u * radius[:, None], F


SPHERE = _star_cage(42, 0.0)
STAR = _star_cage(60, 0.3, seed=1)  # non-convex, star-shaped about the origin


def _inside(V: np.ndarray, F: np.ndarray, n: int, seed: int, *, star: np.ndarray) -> np.ndarray:
    """Points strictly inside a cage star-shaped about ``star``: shrunk surface points."""
    rng = np.random.default_rng(seed)
    b = rng.dirichlet([1, 1, 1], n)
    surf = np.einsum("pk,pki->pi", b, V[F[rng.integers(0, len(F), n)]])
    return star + rng.uniform(0.02, 0.97, (n, 1)) * (surf - star)


CAGES = {
    "cube": (CUBE_V, CUBE_F, np.full(3, 0.5)),
    "octahedron": (OCTA_V, OCTA_F, np.zeros(3)),
    "sphere": (*SPHERE, np.zeros(3)),
    "star": (*STAR, np.zeros(3)),
}


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


# ------------------------------------------------------------------------ coordinates
@pytest.mark.parametrize("name", list(CAGES))
def test_reproduces_points_at_rest(name):
    V, F, c = CAGES[name]
    P = _inside(V, F, 300, seed=3, star=c)
    phi, psi = green_coordinates(P, V, F)
    assert phi.shape == (300, len(V)) and psi.shape == (300, len(F))
    assert phi.dtype == psi.dtype == np.float64
    np.testing.assert_allclose(phi @ V + psi @ _normals(V, F), P, rtol=0, atol=1e-9)
    np.testing.assert_allclose(phi.sum(axis=1), 1.0, rtol=0, atol=1e-12)  # partition of unity
    assert np.all(psi > 0)  # single-layer potentials of positive densities


def test_matches_quadrature_of_the_green_integrals():
    """φ_i = Σ ∫ Γ_i ∂G/∂n dσ and ψ_j = −∫ G dσ, G = −1/(4π r), by brute-force quadrature."""
    V, F = OCTA_V, OCTA_F
    g, wg = np.polynomial.legendre.leggauss(60)
    s, t = np.meshgrid((g + 1) / 2, (g + 1) / 2, indexing="ij")
    w = np.outer(wg, wg).ravel() / 4 * s.ravel()
    s, t = s.ravel(), t.ravel()
    bary = np.stack([1 - s, s * (1 - t), s * t], axis=1)  # Duffy map of the triangle
    N = _normals(V, F)
    # inside, and outside with raw (unextended) coordinates: the integrals hold everywhere
    for eta, exterior in [(np.array([0.1, -0.2, 0.25]), "extend"), (np.full(3, 0.9), "raw")]:
        phi_q, psi_q = np.zeros(len(V)), np.zeros(len(F))
        for j, f in enumerate(F):
            xi = bary @ V[f]
            area2 = np.linalg.norm(np.cross(V[f[1]] - V[f[0]], V[f[2]] - V[f[0]]))
            r = np.linalg.norm(xi - eta, axis=1)
            psi_q[j] = area2 * np.sum(w / r) / (4 * np.pi)
            dGdn = (xi - eta) @ N[j] / (4 * np.pi * r**3)
            phi_q[f] += area2 * (w * dGdn) @ bary
        phi, psi = green_coordinates(eta[None], V, F, exterior=exterior)
        np.testing.assert_allclose(phi[0], phi_q, rtol=0, atol=1e-10)
        np.testing.assert_allclose(psi[0], psi_q, rtol=0, atol=1e-10)


def test_results_do_not_depend_on_chunking_or_position():
    V, F = STAR
    P = _inside(V, F, 40, seed=4, star=np.zeros(3))
    ref = green_coordinates(P, V, F)
    for chunk in (1, 7):
        for a, b in zip(ref, green_coordinates(P, V, F, chunk_size=chunk), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
    # translation invariance: the same cage and points 1 km away (world-frame offsets)
    far = green_coordinates(P + 1000.0, V + 1000.0, F)
    for a, b in zip(ref, far, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10)


# ------------------------------------------------------------------------ near the cage
DELTAS = [1e-3, 1e-4, 1e-5, 1e-6]


def _near_cube_top(delta: float, sign: float) -> np.ndarray:
    """Points ``delta`` below (sign=+1) or above (sign=−1) the cube's top face z = 1:
    over the face interior, 1e-7 beside an edge, and next to a corner."""
    z = 1.0 - sign * delta
    return np.array([[0.3, 0.4, z], [0.5, 1e-7, z], [delta, delta, z]])


def test_near_face_points_are_finite_accurate_and_continuous():
    """Points 1e-3…1e-6 inside and outside the top face (interior, by an edge, by a corner)."""
    N = _normals(CUBE_V, CUBE_F)
    prev = None
    for delta in DELTAS:
        inner = green_coordinates(_near_cube_top(delta, +1), CUBE_V, CUBE_F)
        outer = green_coordinates(_near_cube_top(delta, -1), CUBE_V, CUBE_F)  # extended
        for (phi, psi), sign in [(inner, +1), (outer, -1)]:
            assert np.all(np.isfinite(phi)) and np.all(np.isfinite(psi))
            P = _near_cube_top(delta, sign)
            np.testing.assert_allclose(phi @ CUBE_V + psi @ N, P, rtol=0, atol=1e-9)
            np.testing.assert_allclose(phi.sum(axis=1), 1.0, rtol=0, atol=1e-9)
        # continuity across the face: inside and extended outside values 2δ apart differ
        # by O(δ) (measured ≤ 5.4 δ; the gradient grows like log δ by an edge or a corner)
        assert np.abs(np.hstack(inner) - np.hstack(outer)).max() < 10 * delta
        if prev is not None:  # approaching the face the values converge (measured ≤ 6 × 10δ)
            assert np.abs(np.hstack(inner) - prev).max() < 100 * delta
        prev = np.hstack(inner)


def test_points_on_the_cage_get_the_interior_limit():
    """Exactly on a face, on an edge (incl. a flat diagonal) or at a vertex: the solid angles
    are undefined there; such points (within 1e-7 × diameter) get the interior limit."""
    on = np.array([[0.3, 0.4, 1.0], [0.5, 0.5, 0.0], [0.0, 0.5, 0.0], [0, 0, 0], [1, 0.3, 0.3]])
    inside = np.array(
        [
            [0.3, 0.4, 1 - 1e-6],
            [0.5, 0.5, 1e-6],
            [1e-6, 0.5, 1e-6],
            [1e-6] * 3,
            [1 - 1e-6, 0.3, 0.3],
        ]
    )
    d = GreenDeformer(CUBE_V, CUBE_F, np.vstack([on, on + 1e-9, inside]))
    assert np.all(np.isfinite(d.phi_)) and np.all(np.isfinite(d.psi_))
    assert not d.outside_[:5].any()
    np.testing.assert_allclose(d.deform(CUBE_V)[:10], np.vstack([on, on + 1e-9]), atol=1e-9)
    np.testing.assert_allclose(d.phi_.sum(axis=1), 1.0, atol=1e-9)
    # the limit: coordinates and deformed positions match points 1e-6 inside to O(1e-6 log)
    # (measured 3.7e-6 and 1.4e-6) and points 1e-9 off the cage to O(1e-9) (measured 1.4e-9)
    G = np.hstack([d.phi_, d.psi_])
    assert np.abs(G[:5] - G[10:]).max() < 2e-5
    Vn = CUBE_V + 0.1 * np.random.default_rng(2).normal(size=CUBE_V.shape)
    X = d.deform(Vn)
    assert np.abs(X[:5] - X[10:]).max() < 1e-5 and np.abs(X[:5] - X[5:10]).max() < 1e-8


# ------------------------------------------------------------------------ exterior
def test_exterior_points_extended_raw_or_refused():
    V, F = CUBE_V, CUBE_F
    out = np.array([[0.5, 0.5, 1.05], [-0.02, 0.3, 0.6], [0.4, 1.1, 0.5]])
    P = np.vstack([out, [[0.5, 0.5, 0.5]]])
    d = GreenDeformer(V, F, P)
    assert d.outside_.tolist() == [True, True, True, False]
    np.testing.assert_allclose(d.deform(V), P, rtol=0, atol=1e-12)
    # the continuation is exact under similarities too
    R, k, t = _rotation(5), 1.7, np.array([0.3, -2.0, 1.0])
    np.testing.assert_allclose(d.deform(k * V @ R.T + t), k * P @ R.T + t, atol=1e-9)
    # raw: Green's identity outside the domain reproduces 0 and Σφ = 0
    phi, psi = green_coordinates(out, V, F, exterior="raw")
    np.testing.assert_allclose(phi.sum(axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(phi @ V + psi @ _normals(V, F), 0.0, atol=1e-12)
    with pytest.raises(InputError, match="3 points lie outside the cage"):
        green_coordinates(P, V, F, exterior="raise")


# ------------------------------------------------------------------------ deformation
@pytest.mark.parametrize("name", ["cube", "sphere", "star"])
def test_deformation_is_exact_under_similarities(name):
    V, F, c = CAGES[name]
    P = _inside(V, F, 200, seed=6, star=c)
    d = GreenDeformer(V, F, P)
    np.testing.assert_allclose(d.deform(V), P, rtol=0, atol=1e-9)
    R, t = _rotation(7), np.array([2.0, -1.0, 0.5])
    for k in (1.0, 0.5, 3.0):
        for RR in (np.eye(3), R):
            Vn = k * V @ RR.T + t
            np.testing.assert_allclose(d.stretch_factors(Vn), k, rtol=1e-12)
            np.testing.assert_allclose(d.deform(Vn), k * P @ RR.T + t, rtol=0, atol=1e-9 * k)


def test_stretch_factor_is_rms_of_in_plane_singular_values():
    """GC08: s = sqrt(|u'|²|v|² − 2(u'·v')(u·v) + |v'|²|u|²)/(√8 A) = ‖J‖_F/√2 for the
    face's 2D linear map J (derived independently: Q = 4A² tr(JᵀJ))."""
    V, F = SPHERE
    d = GreenDeformer(V, F, np.zeros((1, 3)))
    rng = np.random.default_rng(8)
    Vn = V + 0.1 * rng.normal(size=V.shape)
    s = d.stretch_factors(Vn)
    for j in range(0, len(F), 7):
        U = np.stack([d.rest_u_[j], d.rest_v_[j]], axis=1)  # (3, 2)
        Un = np.stack([Vn[F[j, 1]] - Vn[F[j, 0]], Vn[F[j, 2]] - Vn[F[j, 0]]], axis=1)
        J = Un @ np.linalg.pinv(U)  # maps the rest face plane onto the deformed one
        np.testing.assert_allclose(s[j], np.linalg.norm(J) / np.sqrt(2), rtol=1e-12)
    # the literal GC08 expression, on the well-shaped cube faces
    d = GreenDeformer(CUBE_V, CUBE_F, np.full((1, 3), 0.5))
    Vn = CUBE_V + 0.2 * rng.normal(size=CUBE_V.shape)
    u, v = d.rest_u_, d.rest_v_
    un, vn = (Vn[CUBE_F[:, k]] - Vn[CUBE_F[:, 0]] for k in (1, 2))
    dot = lambda a, b: np.sum(a * b, axis=1)  # noqa: E731
    Q = dot(un, un) * dot(v, v) - 2 * dot(un, vn) * dot(u, v) + dot(vn, vn) * dot(u, u)
    np.testing.assert_allclose(d.stretch_factors(Vn), np.sqrt(Q) / (np.sqrt(8) * d.rest_area_))


def test_batched_deform_matches_single_cages():
    V, F = STAR
    P = _inside(V, F, 50, seed=13, star=np.zeros(3))
    d = GreenDeformer(V, F, P)
    Vs = V + 0.05 * np.random.default_rng(14).normal(size=(3, *V.shape))
    X = d.deform(Vs)
    assert X.shape == (3, 50, 3) and d.stretch_factors(Vs).shape == (3, len(F))
    for k in range(3):
        np.testing.assert_allclose(X[k], d.deform(Vs[k]), rtol=0, atol=1e-14)
        np.testing.assert_allclose(d.stretch_factors(Vs)[k], d.stretch_factors(Vs[k]), rtol=1e-15)


def test_float32_storage_is_close():
    V, F = STAR
    P = _inside(V, F, 500, seed=9, star=np.zeros(3))
    Vn = V + 0.05 * np.random.default_rng(10).normal(size=V.shape)
    d64, d32 = GreenDeformer(V, F, P), GreenDeformer(V, F, P, dtype=np.float32)
    ref, fast = d64.deform(Vn), d32.deform(Vn)
    assert fast.dtype == np.float64 and fast.flags.c_contiguous
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-5)  # float32: ~1e-7 × sums of ~100
    # derivatives: float64 arithmetic on the stored (float32) coordinates, ~1e-7 relative
    assert d32.phi_.dtype == np.float32  # no float64 copy: half the memory
    G = np.ones_like(P)
    np.testing.assert_allclose(d32.vjp(Vn, G), d64.vjp(Vn, G), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(d32.jvp(Vn, Vn), d64.jvp(Vn, Vn), rtol=1e-5, atol=1e-6)


# ------------------------------------------------------------------------ derivatives
def test_jvp_vjp_and_jacobian_match_finite_differences():
    V, F = SPHERE
    rng = np.random.default_rng(11)
    P = _inside(V, F, 25, seed=12, star=np.zeros(3))
    d = GreenDeformer(V, F, P)
    Vn = V + 0.1 * rng.normal(size=V.shape)
    dV = rng.normal(size=V.shape)
    eps = 1e-6
    fd = (d.deform(Vn + eps * dV) - d.deform(Vn - eps * dV)) / (2 * eps)
    jv = d.jvp(Vn, dV)
    np.testing.assert_allclose(jv, fd, rtol=0, atol=1e-6 * np.abs(fd).max())
    J = d.jacobian(Vn)
    assert J.shape == (25, 3, len(V), 3)
    np.testing.assert_allclose(np.einsum("paib,ib->pa", J, dV), jv, atol=1e-12)
    G = rng.normal(size=P.shape)
    np.testing.assert_allclose(d.vjp(Vn, G), np.einsum("paib,pa->ib", J, G), atol=1e-12)
    # with normals and stretch factors held fixed the operator is phi_ on each axis
    s_n = d.stretch_factors(Vn)[:, None] * _normals(Vn, F)
    np.testing.assert_allclose(d.deform(Vn), d.phi_ @ Vn + d.psi_ @ s_n, atol=1e-12)


# ------------------------------------------------------------------------ errors
def test_bad_inputs_raise_one_line_errors():
    V, F = CUBE_V, CUBE_F
    P = np.full((2, 3), 0.5)
    cases = [
        (MeshError, "holes", lambda: green_coordinates(P, V, F[:-1])),  # open cage
        (MeshError, "consistently oriented", lambda: green_coordinates(P, V, _flip(F, [0]))),
        (MeshError, "outward", lambda: green_coordinates(P, V, F[:, ::-1])),
        (InputError, r"points must have shape \(n, 3\)", lambda: green_coordinates(P[:, :2], V, F)),
        (InputError, "NaN", lambda: green_coordinates(np.full((1, 3), np.nan), V, F)),
        (InputError, "cage_F must be", lambda: green_coordinates(P, V, F.astype(float))),
        (InputError, "exterior must be one of", lambda: green_coordinates(P, V, F, exterior="x")),
        (InputError, "chunk_size", lambda: green_coordinates(P, V, F, chunk_size=0)),
        (InputError, "dtype", lambda: GreenDeformer(V, F, P, dtype=np.int32)),
        (InputError, r"cage_V_new must have shape", lambda: GreenDeformer(V, F, P).deform(V[1:])),
        (InputError, "grad_points", lambda: GreenDeformer(V, F, P).vjp(V, np.zeros((3, 3)))),
    ]
    for cls, pattern, call in cases:
        with pytest.raises(cls, match=pattern) as info:
            call()
        assert isinstance(info.value, ValueError) and "\n" not in str(info.value)


def _flip(F: np.ndarray, rows: list[int]) -> np.ndarray:
    F = F.copy()
    F[rows] = F[rows][:, ::-1]
    return F


def test_a_large_point_set_is_computed_in_chunks_in_bounded_memory():
    import tracemalloc

    V, F = STAR  # 116 faces, 60 vertices
    rng = np.random.default_rng(21)
    P = _inside(V, F, 40_000, seed=22, star=np.zeros(3))
    P[:50] = 1.5 * V[F[:50, 0]]  # outside: extended through their nearest face
    one = GreenDeformer(V, F, P[:3000], chunk_size=3000)  # a single chunk
    many = GreenDeformer(V, F, P[:3000], chunk_size=7)  # 429 chunks
    np.testing.assert_allclose(many.phi_, one.phi_, rtol=0, atol=1e-15)
    np.testing.assert_allclose(many.psi_, one.psi_, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(many.outside_, one.outside_)
    store = 4 * len(P) * (len(V) + len(F))  # float32 coordinates: 28 MB
    tracemalloc.start()
    try:
        d = GreenDeformer(V, F, P, dtype=np.float32)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # the coordinates and one default chunk's temporaries (~16 MB), no full-size float64
    # copy (a float64 result and its float32 cast would take 3 × store)
    assert store < peak < store + 24e6, (store, peak)
    Vn = V + 0.05 * rng.normal(size=V.shape)
    np.testing.assert_allclose(d.deform(Vn)[:3000], one.deform(Vn), rtol=0, atol=2e-5)
