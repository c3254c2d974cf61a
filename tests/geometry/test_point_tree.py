"""The nearest agreeing point of meshmocap.geometry.point_tree against pykdtree's two-query
answer (meshmocap.body.articulated.nearest_compatible), with and without guesses."""

import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from meshmocap.body.articulated import nearest_compatible
from meshmocap.errors import InputError
from meshmocap.geometry.point_tree import nearest_agreeing, point_tree

RNG = np.random.default_rng(11)


def _unit(n: int) -> np.ndarray:
    u = RNG.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _kd_answer(X, NX, Q, NQ, **cand) -> np.ndarray:
    """What the ICP tracker asked of pykdtree: each query's point, −1 where none."""
    found = np.full(len(Q), -1, dtype=np.int64)
    q, p = nearest_compatible(KDTree(X), NX, Q, NQ, **cand)
    found[q] = p
    return found


def _surface(n: int) -> np.ndarray:
    """Points near a surface (a sphere's and a slab's: a hull's), some far outliers."""
    s = _unit(n) * [0.3, 0.8, 0.2]
    slab = RNG.uniform(-1, 1, (n // 4, 3)) * [0.5, 0.02, 0.5]
    far = RNG.uniform(-2, 2, (n // 20, 3))
    return np.concatenate([s, slab, far])


@pytest.mark.parametrize("k", [1, 3, 8])
@pytest.mark.parametrize("max_distance", [0.01, 0.1, 10.0])
@pytest.mark.parametrize("normal_cos", [-0.5, 0.3, 0.9])
def test_nearest_agreeing_is_pykdtrees_two_query_answer(k, max_distance, normal_cos):
    """Clustered points and queries near and far: the same answer as pykdtree's nearest
    query with a k-nearest query where the nearest disagrees; every guess (none, random
    points, the answer itself, the answer for moved queries) gives the same answer."""
    X, Q = _surface(1200), _surface(900)
    Q = Q + RNG.normal(scale=0.02, size=Q.shape)
    NX, NQ = _unit(len(X)), _unit(len(Q))
    cand = dict(k=k, max_distance=max_distance, normal_cos=normal_cos)
    want = _kd_answer(X, NX, Q, NQ, **cand)
    tree = point_tree(X, NX)
    assert np.array_equal(nearest_agreeing(tree, Q, NQ, **cand), want)
    for hint in (
        RNG.integers(-1, len(X), len(Q)),
        want,
        _kd_answer(X, NX, Q + RNG.normal(scale=0.01, size=Q.shape), NQ, **cand),
    ):
        assert np.array_equal(nearest_agreeing(tree, Q, NQ, hint=hint, **cand), want)
    assert (want >= 0).any() and (max_distance > 5 or (want < 0).any())


@pytest.mark.parametrize("leaf_size", [1, 4, 32, 5000])
def test_every_leaf_size_and_repeated_points_give_the_same_answer(leaf_size):
    """Points repeated (a leaf that cannot split) and points one rounding step apart."""
    X = np.concatenate([_surface(400), np.repeat(RNG.normal(size=(3, 3)) * 0.1, 60, axis=0)])
    X[-5:] = X[-6] + np.spacing(X[-6]) * np.arange(1, 6)[:, None]
    NX = np.abs(_unit(len(X)))
    NX[-180:] = np.repeat(NX[-180::60], 60, axis=0)  # a repeated point: one normal
    Q = X[RNG.integers(0, len(X), 600)] + RNG.normal(scale=0.05, size=(600, 3))
    NQ = np.abs(_unit(len(Q)))
    cand = dict(k=8, max_distance=0.2, normal_cos=0.3)
    tree = point_tree(X, NX, leaf_size=leaf_size)
    assert tree.n == len(X) and tree.depth >= 0
    assert np.array_equal(np.sort(tree.order), np.arange(len(X)))
    assert np.array_equal(tree.order[tree.rank], np.arange(len(X)))
    got = nearest_agreeing(tree, Q, NQ, **cand)
    want = _kd_answer(X, NX, Q, NQ, **cand)
    # repeated points lie at equal distances: either of them answers, at the same distance
    same = got == want
    d = np.linalg.norm(X[np.maximum(got, 0)] - Q, axis=1)
    e = np.linalg.norm(X[np.maximum(want, 0)] - Q, axis=1)
    assert np.array_equal(got >= 0, want >= 0)
    assert np.array_equal(d[~same], e[~same]) and same.any()


def test_a_single_point_and_no_query():
    X, N = np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]])
    tree = point_tree(X, N)
    Q = np.array([[0.0, 0.0, 0.95], [0.0, 0.0, 0.5], [0.0, 0.0, 0.99]])
    NQ = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    got = nearest_agreeing(tree, Q, NQ, k=8, max_distance=0.1, normal_cos=0.3)
    assert got.tolist() == [0, -1, -1]
    empty = np.empty((0, 3))
    assert nearest_agreeing(tree, empty, empty, k=8, max_distance=0.1, normal_cos=0.3).shape == (0,)


def test_bad_input_is_named():
    X, N = RNG.normal(size=(10, 3)), _unit(10)
    tree = point_tree(X, N)
    cand = dict(k=8, max_distance=0.1, normal_cos=0.3)
    with pytest.raises(InputError, match="point_tree: expected points"):
        point_tree(X[:, :2], N)
    with pytest.raises(InputError, match="point_tree: expected points"):
        point_tree(np.empty((0, 3)), np.empty((0, 3)))
    with pytest.raises(InputError, match="finite"):
        point_tree(np.full((2, 3), np.nan), N[:2])
    with pytest.raises(InputError, match="leaf_size"):
        point_tree(X, N, leaf_size=0)
    with pytest.raises(InputError, match="nearest_agreeing: expected query points"):
        nearest_agreeing(tree, X, N[:3], **cand)
    with pytest.raises(InputError, match="k ≥ 1"):
        nearest_agreeing(tree, X, N, k=0, max_distance=0.1, normal_cos=0.3)
    with pytest.raises(InputError, match="hint"):
        nearest_agreeing(tree, X, N, hint=np.full(10, 10), **cand)
