"""The output surface refined towards observations along its normals (geometry/refine.py)."""

import numpy as np
import pytest
import trimesh

from meshmocap.errors import InputError
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.refine import ArapRefiner, SurfaceRefiner, rotational_part


@pytest.fixture(scope="module")
def sphere():
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.2)  # 642 vertices, ~2 cm apart
    return np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64)


def _observed(radius: float, n: int = 4000, seed: int = 0):
    """Points of a sphere of ``radius`` (m) at random, with outward normals."""
    x = np.random.default_rng(seed).normal(size=(n, 3))
    N = x / np.linalg.norm(x, axis=1, keepdims=True)
    return radius * N, N


def test_a_surface_inside_its_observation_moves_out_onto_it(sphere):
    V, F = sphere
    P, N = _observed(0.215)  # 15 mm further out
    out = SurfaceRefiner(F, len(V)).refine(V, P, N)
    r = np.linalg.norm(out, axis=1)
    # the pull back to the tracked surface (stiffness 0.05 against ~2 matches) keeps it a
    # few per cent of the way short; the sampled points' scatter adds under a millimetre
    assert np.abs(r - 0.215).mean() < 1.5e-3 and np.abs(r - 0.215).max() < 4e-3
    # along the normals only: each vertex moves along its own normal
    n = vertex_normals(V, F)
    d = out - V
    np.testing.assert_allclose(d, np.einsum("ij,ij->i", d, n)[:, None] * n, atol=1e-12)


def test_what_is_not_observed_stays_where_the_skeleton_put_it(sphere):
    V, F = sphere
    P, N = _observed(0.215)
    top = P[:, 2] > 0.05  # only the top is seen
    out = SurfaceRefiner(F, len(V)).refine(V, P[top], N[top])
    r = np.linalg.norm(out, axis=1)
    assert np.abs(r[V[:, 2] > 0.1] - 0.215).max() < 4e-3
    # the displacement fades away from what is seen (smooth, pulled back to the skin)
    top, side, bottom = (
        r[m].mean() - 0.2 for m in (V[:, 2] > 0.1, np.abs(V[:, 2]) < 0.03, V[:, 2] < -0.15)
    )
    assert top > side > bottom and bottom < 0.6 * top


def test_nothing_observed_or_nothing_compatible_leaves_the_surface(sphere):
    V, F = sphere
    ref = SurfaceRefiner(F, len(V))
    np.testing.assert_array_equal(ref.refine(V, np.zeros((0, 3)), np.zeros((0, 3))), V)
    P, N = _observed(0.21)
    # normals pointing inwards: another surface (the inside of a sleeve), not this one
    np.testing.assert_array_equal(ref.refine(V, P, -N), V)
    far, _ = _observed(0.4)  # 20 cm away: out of reach
    np.testing.assert_array_equal(ref.refine(V, far, N), V)


def test_a_refined_surface_keeps_its_detail(sphere):
    """A bump on the tracked surface rides along: the displacement is smooth, the shape
    under it is the template's."""
    V, F = sphere
    bumped = V.copy()
    bumped[0] *= 1.05  # 1 cm bump at one vertex
    P, N = _observed(0.21)
    out = SurfaceRefiner(F, len(V)).refine(bumped, P, N)
    n = vertex_normals(bumped, F)
    # the bump's vertex moved out by about as much as its neighbours (a smooth field)
    u = np.einsum("ij,ij->i", out - bumped, n)
    assert abs(u[0] - np.median(u)) < 6e-3 and np.linalg.norm(out[0]) > 0.214


def test_bad_arguments_are_refused_in_one_line(sphere):
    V, F = sphere
    with pytest.raises(InputError, match="F must be"):
        SurfaceRefiner(F, 10)
    with pytest.raises(InputError, match="reach must be > 0"):
        SurfaceRefiner(F, len(V), reach=0.0)
    with pytest.raises(InputError, match="iterations"):
        SurfaceRefiner(F, len(V), iterations=0)


# ------------------------------------------------------------------ as rigid as possible
@pytest.fixture(scope="module")
def ellipsoid():
    """An ellipsoid (15 × 25 × 40 cm semi-axes, 642 vertices) and dense points of it with
    outward normals: a shape on which a vertex slid along the surface can be told apart."""
    axes = np.array([0.15, 0.25, 0.4])
    s = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    V, F = np.asarray(s.vertices) * axes, np.asarray(s.faces, np.int64)
    fine = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    P = np.asarray(fine.vertices) * axes
    N = P / axes**2  # the gradient of Σ (x/a)²
    return V, F, P, N / np.linalg.norm(N, axis=1, keepdims=True)


def _turn(deg: float, axis: int = 2) -> np.ndarray:
    w = np.zeros(3)
    w[axis] = np.radians(deg)
    from meshmocap.geometry.rotations import so3_exp

    return so3_exp(w)


def test_rotational_part_is_the_polar_rotation():
    rng = np.random.default_rng(0)
    from meshmocap.geometry.rotations import so3_exp

    Q = so3_exp(rng.normal(size=(50, 3)))
    S = rng.normal(size=(50, 3, 3)) * 0.2
    A = Q @ (np.eye(3) + S @ np.swapaxes(S, 1, 2))  # a rotation times a symmetric PD matrix
    R = rotational_part(A, np.tile(np.eye(3), (50, 1, 1)), iterations=40)
    np.testing.assert_allclose(R, Q, atol=1e-8)
    U, _, Vt = np.linalg.svd(A)
    np.testing.assert_allclose(R, U @ Vt, atol=1e-8)


def test_the_local_step_finds_a_rigid_turn_of_the_rest_shape(ellipsoid):
    V, F, _, _ = ellipsoid
    Q = _turn(70.0, 0) @ _turn(40.0)
    ref = ArapRefiner(V, F)
    # a rigid turn's rotation at once, from the rest neighbourhoods' own axes
    R = ref.rotations(V @ Q.T + 0.3, iterations=0)
    np.testing.assert_allclose(R, np.broadcast_to(Q, R.shape), atol=1e-12)
    # a stretch: the polar rotation of each neighbourhood's Aᵢ, as rotational_part finds it
    X = (V * [1.3, 1.0, 0.8]) @ Q.T
    R = ref.rotations(X, iterations=30)
    a, b = ref.edges_.T
    outer = (X[a] - X[b])[:, :, None] * ref.rest_edges_[:, None, :]
    A = np.zeros((len(V), 3, 3))
    np.add.at(A, a, outer)
    np.add.at(A, b, outer)
    U, _, Vt = np.linalg.svd(A)
    # (the update converges slowly where a neighbourhood is flat: Aᵢ has rank 2)
    np.testing.assert_allclose(R, U @ Vt, atol=1e-4)


def _twisted(V: np.ndarray, deg: float = 12.0) -> np.ndarray:
    """``V`` twisted about Z: turned by ``deg`` at the top (z = 40 cm), ``−deg`` at the
    bottom, in between in proportion to z."""
    from meshmocap.geometry.rotations import so3_exp

    w = np.zeros((len(V), 3))
    w[:, 2] = np.radians(deg) * V[:, 2] / 0.4
    return np.einsum("nij,nj->ni", so3_exp(w), V)


def test_a_vertex_slid_along_the_body_goes_back_to_its_place(ellipsoid):
    """The tracked surface is the true one twisted (±12° at the ends): its vertices are
    14 mm off, mostly along the surface. Along the normals nothing can bring them back; as
    rigidly as possible, the rest shape does, more with more iterations."""
    V, F, P, N = ellipsoid
    S = _twisted(V)
    err = lambda X: np.linalg.norm(X - V, axis=1).mean()  # noqa: E731
    normal = SurfaceRefiner(F, len(V)).refine(S, P, N)
    few, many = (ArapRefiner(V, F, iterations=k).refine(S, P, N) for k in (10, 30))
    assert err(S) > 0.013
    assert err(normal) > 0.9 * err(S)
    assert err(many) < err(few) < 0.8 * err(S) and err(many) < 0.5 * err(S)
    # the nearest points searched for every 4th iteration only: nearly as far back
    sparse = ArapRefiner(V, F, iterations=30, search_every=4).refine(S, P, N)
    assert err(sparse) < 1.1 * err(many)


@pytest.mark.parametrize("anchor", ["rest", "previous"])
def test_the_next_frame_starts_where_the_last_left(ellipsoid, anchor):
    """With the frame's number, a frame next to the last one refined starts from that
    refinement (turned with the skin); any other frame starts from the skin alone. Kept
    against the rest shape, the next frame goes further back to it."""
    V, F, P, N = ellipsoid
    S = _twisted(V)
    fresh = ArapRefiner(V, F, iterations=3, anchor=anchor).refine(S, P, N)
    ref = ArapRefiner(V, F, iterations=3, anchor=anchor)
    first = ref.refine(S, P, N, key=4)
    np.testing.assert_array_equal(first, fresh)
    np.testing.assert_array_equal(ref.refine(S, P, N, key=6), fresh)  # not next to 4
    ref.refine(S, P, N, key=4)
    nxt = ref.refine(S, P, N, key=5)
    err = lambda X: np.linalg.norm(X - V, axis=1).mean()  # noqa: E731
    assert err(nxt) < (0.95 if anchor == "rest" else 1.01) * err(fresh)
    # a turned frame carries the refinement turned with it
    Q = _turn(30.0, 1)
    ref = ArapRefiner(V, F, iterations=3, anchor=anchor)
    ref.refine(S, P, N, key=4)
    turned = ref.refine(S @ Q.T, P @ Q.T, N @ Q.T, key=5)
    np.testing.assert_allclose(turned, nxt @ Q.T, atol=1e-6)


def _stretched(V: np.ndarray, k: int, fine: np.ndarray, axes: np.ndarray):
    """Frame ``k`` of an ellipsoid growing 4 % a frame in height and losing 2 % in width
    (not a rigid turn of any neighbourhood of the rest shape): its vertices, and dense
    points of it with outward normals."""
    g = np.array([1 - 0.02 * k, 1.0, 1 + 0.04 * k])
    a = axes * g
    P = fine * a
    N = P / a**2
    return V * g, P, N / np.linalg.norm(N, axis=1, keepdims=True)


def test_anchored_to_the_frame_before_the_vertices_keep_their_place(ellipsoid):
    """A body that changes shape frame by frame, its skin true every frame: kept against
    the template's rest shape the refinement slides the vertices along the surface to make
    the new shape as rigid as the rest; kept against the frame before's surface they slide
    less (measured 25.5 vs 29.6 mm at frame 6)."""
    V, F, _, _ = ellipsoid
    axes = np.array([0.15, 0.25, 0.4])
    fine = np.asarray(trimesh.creation.icosphere(subdivisions=5, radius=1.0).vertices)
    last = {}
    for anchor in ("rest", "previous"):
        ref = ArapRefiner(V, F, anchor=anchor)
        for k in range(7):
            T, P, N = _stretched(V, k, fine, axes)
            last[anchor] = np.linalg.norm(ref.refine(T, P, N, key=k) - T, axis=1).mean()
    assert last["previous"] < 0.92 * last["rest"]


def test_over_relaxed_steps_go_further_in_as_many_iterations(ellipsoid):
    V, F, P, N = ellipsoid
    S = _twisted(V)
    err = lambda X: np.linalg.norm(X - V, axis=1).mean()  # noqa: E731
    plain, relaxed = (
        ArapRefiner(V, F, iterations=10, relaxation=w).refine(S, P, N) for w in (1.0, 1.8)
    )
    assert err(relaxed) < 0.9 * err(plain)


def test_arap_refiner_leaves_a_surface_without_observations(ellipsoid):
    V, F, _, _ = ellipsoid
    S = V @ _turn(8.0).T
    np.testing.assert_array_equal(
        ArapRefiner(V, F).refine(S, np.zeros((0, 3)), np.zeros((0, 3))), S
    )


def test_arap_refiner_refuses_bad_arguments_in_one_line(ellipsoid):
    V, F, _, _ = ellipsoid
    for kw, msg in (
        (dict(data_weight=0.0), "data_weight must be > 0"),
        (dict(stiffness=-1.0), "stiffness must be ≥ 0"),
        (dict(iterations=0), "iterations must be ≥ 1"),
        (dict(max_angle=0.0), "max_angle"),
        (dict(search_every=0), "search_every must be an integer ≥ 1"),
        (dict(search_every=2.0), "search_every must be an integer ≥ 1"),
        (dict(anchor="skin"), "anchor"),
        (dict(relaxation=2.0), "relaxation must be in"),
    ):
        with pytest.raises(InputError, match=msg):
            ArapRefiner(V, F, **kw)
    with pytest.raises(InputError, match="F must be"):
        ArapRefiner(V[:10], F)
