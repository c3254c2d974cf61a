"""The fixed-radius test of meshmocap.geometry.nearby against pykdtree's queries, bounded
at the radius and not."""

import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from meshmocap.errors import InputError
from meshmocap.geometry.nearby import farther_than

RNG = np.random.default_rng(5)


def _kd_farther(Y: np.ndarray, X: np.ndarray, r: float, at_radius: str = "far") -> np.ndarray:
    """What the body-part partition asked of pykdtree, the bounded nearest distance > r
    (``far``), and the fit-quality check, the unbounded one (``near``)."""
    bound = r if at_radius == "far" else np.inf
    d, _ = KDTree(X).query(Y, k=1, distance_upper_bound=bound)
    return d > r


@pytest.mark.parametrize("at_radius", ["far", "near"])
@pytest.mark.parametrize("scale", [0.01, 1.0, 1000.0])
@pytest.mark.parametrize("radius", [1e-4, 0.03, 0.05, 0.3, 5.0])
def test_farther_than_is_the_kd_query(scale, radius, at_radius):
    """Clustered and spread points, query points anywhere, and query points placed at the
    radius itself from a point of X (give or take the last bits): the same answers as
    pykdtree's query bounded at the radius (``far``) or unbounded (``near``), both ways of
    the boundary."""
    X = np.concatenate([RNG.normal(size=(300, 3)) * [1.0, 0.3, 0.05], RNG.uniform(-3, 3, (50, 3))])
    X *= scale
    r = radius * scale
    u = RNG.normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    jitter = RNG.choice([-2e-16, -1e-16, 0.0, 1e-16, 2e-16], size=(400, 1))
    Y = np.concatenate(
        [
            RNG.normal(size=(400, 3)) * scale,
            X[RNG.integers(0, len(X), 400)] + u * r * (1.0 + jitter),
        ]
    )
    far = farther_than(Y, X, radius=r, at_radius=at_radius)
    assert np.array_equal(far, _kd_farther(Y, X, r, at_radius))
    assert not far.all()  # some query points lie within the radius (at it, for the largest)


def test_farther_than_on_a_sparse_wide_set():
    """Points kilometres apart with a millimetre radius (the grid's cells grow to bound
    their number) and a single point (a point at exactly the radius is far: the k-d
    query's bound is strict): still the k-d answers."""
    X = RNG.uniform(-1000, 1000, size=(20, 3))
    Y = np.concatenate([X + 5e-4, X + 2e-3, RNG.uniform(-1000, 1000, size=(20, 3))])
    assert np.array_equal(farther_than(Y, X, radius=1e-3), _kd_farther(Y, X, 1e-3))
    one = np.zeros((1, 3))
    Y = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.49], [2.0, 0.0, 0.0]])
    assert farther_than(Y, one, radius=0.5).tolist() == [True, False, True]  # at r: far
    assert np.array_equal(farther_than(Y, one, radius=0.5), _kd_farther(Y, one, 0.5))
    near = farther_than(Y, one, radius=0.5, at_radius="near")
    assert near.tolist() == [False, False, True]  # d = r is not d > r
    assert np.array_equal(near, _kd_farther(Y, one, 0.5, "near"))


def test_farther_than_with_nothing_near_and_bad_input():
    """No X: every point is far; no Y: an empty answer; a radius that is not positive or a
    non-finite X is refused naming the argument."""
    assert farther_than(np.zeros((3, 3)), np.zeros((0, 3)), radius=1.0).tolist() == [True] * 3
    assert farther_than(np.zeros((0, 3)), np.zeros((4, 3)), radius=1.0).shape == (0,)
    with pytest.raises(InputError, match="radius"):
        farther_than(np.zeros((1, 3)), np.zeros((1, 3)), radius=0.0)
    with pytest.raises(InputError, match=r"at_radius must be one of \['far', 'near'\]"):
        farther_than(np.zeros((1, 3)), np.zeros((1, 3)), radius=1.0, at_radius="on")
    with pytest.raises(InputError, match="X must be finite"):
        farther_than(np.zeros((1, 3)), np.array([[0.0, np.inf, 0.0]]), radius=1.0)
