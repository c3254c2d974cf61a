"""LazyDistanceGrid: the signed distance transform of an occupancy, evaluated on demand."""

import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from meshmocap.errors import InputError
from meshmocap.geometry.distance_field import (
    DistanceGrid,
    LazyDistanceGrid,
    inner_boundary,
    signed_distance,
)


def _blobs(seed: int, n: int = 24) -> np.ndarray:
    """A non-convex occupancy touching the grid's border (two balls and a bar)."""
    X = np.indices((n, n + 3, n - 2)).reshape(3, -1).T.astype(float)
    occ = np.linalg.norm(X - [7, 8, 9], axis=1) < 6
    occ |= np.linalg.norm(X - [16, 18, 10], axis=1) < 5
    occ |= (np.abs(X[:, 0] - 12) < 1.5) & (np.abs(X[:, 2] - 3) < 2) & (X[:, 1] < 10)
    occ |= np.random.default_rng(seed).random(len(X)) < 0.002  # isolated voxels
    return occ.reshape(n, n + 3, n - 2)


@pytest.mark.parametrize("pad", [1, 3])
def test_same_field_as_the_full_distance_transform(pad):
    occ, origin, h = _blobs(0), np.array([0.1, -0.3, 0.2]), 0.02
    full = DistanceGrid(signed_distance(np.pad(occ, pad), h), origin - pad * h, h)
    lazy = LazyDistanceGrid(occ, origin, h, pad=pad)
    assert lazy.shape == full.shape and np.array_equal(lazy.origin, full.origin)
    rng = np.random.default_rng(1)
    P = lazy.origin + rng.uniform(-0.1, 1.1, (400, 3)) * (lazy.upper - lazy.origin)  # some outside
    v, g = lazy.value_and_gradient(P)
    vf, gf = full.value_and_gradient(P)
    np.testing.assert_allclose(v, vf, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g, gf, rtol=0, atol=1e-9)
    assert 0 < lazy.n_evaluated < np.prod(lazy.shape) and lazy.seconds > 0
    np.testing.assert_allclose(lazy.values, full.values, rtol=0, atol=1e-12)  # every point
    assert lazy.n_evaluated == np.prod(lazy.shape)
    # the boundary points are the voxel centres the field is zero-crossing next to: half a
    # voxel inside the surface, so the field reads -h/2 there (exactly, at grid points)
    np.testing.assert_allclose(lazy(lazy.boundary), -h / 2, rtol=0, atol=1e-12)
    inner = signed_distance(np.pad(occ, 1), h)[1:-1, 1:-1, 1:-1] > -h  # beyond: empty
    assert len(lazy.boundary) == (occ & inner).sum()


@pytest.mark.parametrize("stride", [2, 3])
def test_a_strided_grid_is_the_full_field_subsampled(stride):
    occ, origin, h, pad = _blobs(4), np.array([0.1, -0.3, 0.2]), 0.02, 2
    full = signed_distance(np.pad(occ, pad), h)[::stride, ::stride, ::stride]
    lazy = LazyDistanceGrid(occ, origin, h, pad=pad, stride=stride)
    ref = DistanceGrid(full, origin - pad * h, stride * h)
    assert lazy.shape == ref.shape and np.allclose(lazy.upper, ref.upper, rtol=0, atol=1e-15)
    rng = np.random.default_rng(5)
    P = lazy.origin + rng.uniform(-0.1, 1.1, (400, 3)) * (lazy.upper - lazy.origin)
    v, g = lazy.value_and_gradient(P)
    vf, gf = ref.value_and_gradient(P)
    np.testing.assert_allclose(v, vf, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g, gf, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lazy.values, full, rtol=0, atol=1e-12)
    with pytest.raises(InputError, match="stride"):
        LazyDistanceGrid(occ, origin, h, stride=0)


@pytest.mark.parametrize("shape", [(24, 27, 22), (3, 5, 4), (2, 6, 5), (5, 1, 4), (4, 4, 3)])
def test_inner_boundary_is_the_six_neighbour_definition(shape):
    """The flat-offset computation (wrapping on the border layers) against the definition:
    occupied with an empty 6-neighbour, beyond the grid empty."""
    occ = np.random.default_rng(7).random(shape) < 0.8
    if shape == (24, 27, 22):
        occ = _blobs(2)
    pad = np.pad(occ, 1)
    c = pad[1:-1, 1:-1, 1:-1]
    full = (
        pad[:-2, 1:-1, 1:-1]
        & pad[2:, 1:-1, 1:-1]
        & pad[1:-1, :-2, 1:-1]
        & pad[1:-1, 2:, 1:-1]
        & pad[1:-1, 1:-1, :-2]
        & pad[1:-1, 1:-1, 2:]
    )
    assert np.array_equal(inner_boundary(occ), c & ~full)
    assert np.array_equal(inner_boundary(np.asfortranarray(occ)), c & ~full)


def test_gradient_matches_central_differences_inside_cells():
    lazy = LazyDistanceGrid(_blobs(2), np.zeros(3), 0.05, pad=2)
    rng = np.random.default_rng(3)
    cell = rng.integers(0, np.array(lazy.shape) - 1, (100, 3))
    P = lazy.origin + (cell + rng.uniform(0.1, 0.9, (100, 3))) * lazy.spacing
    _, grad = lazy.value_and_gradient(P)
    h = 1e-6  # trilinear inside a cell: central differences exact up to rounding (~1e-10)
    fd = np.stack([(lazy(P + h * e) - lazy(P - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    assert np.abs(fd - grad).max() < 1e-8


def test_input_errors_are_one_line():
    occ = _blobs(0)
    cases = [
        (lambda: LazyDistanceGrid(np.zeros((4, 4, 4), bool), np.zeros(3), 0.1), "non-empty"),
        (lambda: LazyDistanceGrid(occ, np.zeros(2), 0.1), "origin"),
        (lambda: LazyDistanceGrid(occ, np.zeros(3), -1.0), "spacing"),
        (lambda: LazyDistanceGrid(occ, np.zeros(3), 0.1, pad=0), "pad"),
    ]
    for call, pattern in cases:
        with pytest.raises(InputError, match=pattern) as info:
            call()
        assert "\n" not in str(info.value)


def test_prefetch_moves_the_work_not_the_values():
    occ, origin, h = _blobs(3), np.array([0.1, -0.3, 0.2]), 0.02
    rng = np.random.default_rng(2)
    a, b = (
        LazyDistanceGrid(occ, origin, h, pad=2, stride=2),
        LazyDistanceGrid(occ, origin, h, pad=2, stride=2),
    )
    P = a.origin + rng.uniform(-0.1, 1.1, (300, 3)) * (a.upper - a.origin)  # some outside
    b.prefetch(np.concatenate([P[:150], [[np.nan, 0.0, 0.0]]]))  # non-finite: skipped
    n = b.n_evaluated
    assert 0 < n <= 8 * 150
    va, ga = a.value_and_gradient(P)
    vb, gb = b.value_and_gradient(P)
    assert np.array_equal(va, vb) and np.array_equal(ga, gb)
    assert a.n_evaluated == b.n_evaluated  # the prefetched points were among those needed
    b.prefetch(P)  # nothing new to compute
    assert b.n_evaluated == a.n_evaluated


def test_at_points_looks_around_each_point_then_in_the_tree_with_the_same_distances():
    # the voxels within a few rings first, the k-d tree for points they do not settle:
    # every distance the one the tree alone gives, near the surface, deep inside, far
    # beyond the box
    occ, origin, h, pad = _blobs(6), np.array([0.1, -0.3, 0.2]), 0.02, 2
    lazy = LazyDistanceGrid(occ, origin, h, pad=pad)
    rng = np.random.default_rng(3)
    box = lazy.upper - lazy.origin
    P = np.concatenate(
        [
            lazy.boundary + rng.normal(scale=h, size=lazy.boundary.shape),  # near
            lazy.origin + rng.uniform(-0.5, 1.5, (2000, 3)) * box,  # anywhere, beyond too
            lazy.boundary[:5] + 0.5 * h,  # halfway between voxel centres: ties
        ]
    )
    g = (P - (lazy.origin + pad * h)) / h
    e = KDTree(np.argwhere(inner_boundary(occ)).astype(np.float64)).query(g, k=1)[0]
    ijk = np.round(g).astype(np.intp)
    ok = np.all((ijk >= 0) & (ijk < occ.shape), axis=1)
    inside = np.zeros(len(g), dtype=bool)
    inside[ok] = occ[tuple(ijk[ok].T)]
    np.testing.assert_array_equal(lazy.at_points(P), np.where(inside, -0.5 - e, e - 0.5) * h)


def test_at_points_looks_further_around_a_few_points_before_building_the_tree():
    # a body's vertices: most within a couple of voxels of the surface, a few farther
    # (within AT_POINTS_FAR_RINGS, then beyond): the tree's distances, and the tree built
    # only for those beyond
    occ, origin, h, pad = _blobs(6), np.array([0.1, -0.3, 0.2]), 0.02, 2
    rng = np.random.default_rng(5)
    tree = KDTree(np.argwhere(inner_boundary(occ)).astype(np.float64))
    for beyond in (0, 3):
        lazy = LazyDistanceGrid(occ, origin, h, pad=pad)
        B = lazy.boundary
        far = rng.normal(size=(20 + beyond, 3))
        far *= (rng.uniform(3, 9, len(far)) * h / np.linalg.norm(far, axis=1))[:, None]
        far[20:] *= 4  # 12–36 voxels away
        P = np.concatenate([B[:400] + rng.normal(scale=h / 2, size=(400, 3)), B[: len(far)] + far])
        g = (P - (lazy.origin + pad * h)) / h
        e = tree.query(g, k=1)[0]
        ijk = np.round(g).astype(np.intp)
        ok = np.all((ijk >= 0) & (ijk < occ.shape), axis=1)
        inside = np.zeros(len(g), dtype=bool)
        inside[ok] = occ[tuple(ijk[ok].T)]
        want = np.where(inside, -0.5 - e, e - 0.5) * h
        np.testing.assert_array_equal(lazy.at_points(P), want)
        assert ("_tree" in lazy.__dict__) == bool(beyond)


def test_side_of_answers_as_at_points_values_compared():
    # near the surface, deep inside, far beyond the box, on the thresholds themselves:
    # where the signed distance lies, as at_points' values compared, for several bands
    occ, origin, h, pad = _blobs(6), np.array([0.1, -0.3, 0.2]), 0.02, 2
    rng = np.random.default_rng(11)
    lazy = LazyDistanceGrid(occ, origin, h, pad=pad)
    box = lazy.upper - lazy.origin
    P = np.concatenate(
        [
            lazy.boundary + rng.normal(scale=2 * h, size=lazy.boundary.shape),
            lazy.origin + rng.uniform(-0.5, 1.5, (2000, 3)) * box,
            lazy.boundary[:5] + 0.5 * h,
        ]
    )
    sd = LazyDistanceGrid(occ, origin, h, pad=pad).at_points(P)
    at = [sd[100], sd[200], sd[2000]]  # bands whose ends are values found exactly
    for below, above in ((-0.04, 0.03), (-np.inf, 0.05), (0.0, 0.0), (-0.2, 0.1), at[:2], at[1:]):
        low, high = min(below, above), max(below, above)
        want = np.where(sd > high, 1, np.where(sd < low, -1, 0))
        got = lazy.side_of(P, low, high)
        assert got.dtype == np.int8
        np.testing.assert_array_equal(got, want)
    assert lazy.side_of(P.reshape(-1, 1, 3), -0.04, 0.03).shape == (len(P), 1)
    with pytest.raises(InputError, match="expected finite coordinates"):
        lazy.side_of(np.array([[np.nan, 0.0, 0.0]]), 0.0, 0.0)


def test_at_points_is_the_grid_value_at_grid_points_and_close_between():
    occ, origin, h, pad = _blobs(6), np.array([0.1, -0.3, 0.2]), 0.02, 2
    lazy = LazyDistanceGrid(occ, origin, h, pad=pad)
    rng = np.random.default_rng(7)
    ijk = np.stack([rng.integers(0, n, 300) for n in lazy.shape], axis=1)
    G = lazy.origin + ijk * h  # grid points: the same computation, exactly
    np.testing.assert_allclose(lazy.at_points(G), lazy(G), rtol=0, atol=1e-12)
    inside = lazy.origin + h + rng.uniform(0, 1, (500, 3)) * (lazy.upper - lazy.origin - 2 * h)
    # between grid points: the point's own distance, which the trilinear lookup
    # interpolates; both are within a voxel's diagonal of each other
    d = np.abs(lazy.at_points(inside) - lazy(inside))
    assert d.max() < np.sqrt(3) * h and np.median(d) < h / 2
    far = lazy.upper + [1.0, 0.0, 0.0]  # beyond the box: the distance, not the box's
    assert lazy.at_points(far[None])[0] > 1.0
    assert lazy.at_points(inside.reshape(5, 100, 3)).shape == (5, 100)
    with pytest.raises(InputError, match="expected finite coordinates"):
        lazy.at_points(np.array([[np.nan, 0.0, 0.0]]))
